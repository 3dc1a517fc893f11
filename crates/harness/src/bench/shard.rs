//! Shards: a suite's configurations cut between machines, each scene kept whole.

use std::collections::HashMap;
use std::path::Path;

use super::Config;

/// Shard `index` of `count` of a suite (`bench --shard K/N`, 1-based `K`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// Which shard, 1 ..= `count`.
    pub index: usize,
    /// How many shards.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// Parses `K/N` with 1 <= K <= N.
    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("--shard {s:?}: expected K/N with 1 <= K <= N, e.g. 2/8");
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count): (usize, usize) = (
            k.trim().parse().map_err(|_| bad())?,
            n.trim().parse().map_err(|_| bad())?,
        );
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Self { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// The configurations of shard `shard`: a deterministic partition of `configs` (every
/// configuration in exactly one shard) in which all configurations of one scene file stay
/// together, so each scene's reference renders and rotation blocks are made once. Scenes go
/// to shards greedily, most configurations first, each to the shard with the fewest so far
/// (ties: lowest shard, then suite order). Suite order is kept within a shard.
///
/// Errors: more shards than scene files, the units a suite is split into (checked before
/// anything is allocated per shard): some shard would be empty, so its run would fail and
/// the shards could never be merged. The message gives the largest possible N.
pub fn shard(configs: &[Config], shard: Shard) -> Result<Vec<Config>, String> {
    let mut scene_index: HashMap<&Path, usize> = HashMap::new();
    let mut scenes: Vec<(&Path, usize)> = Vec::new();
    for c in configs {
        let i = *scene_index
            .entry(c.scene_path.as_path())
            .or_insert_with(|| {
                scenes.push((c.scene_path.as_path(), 0));
                scenes.len() - 1
            });
        scenes[i].1 += 1;
    }
    if shard.count > scenes.len() {
        return Err(format!(
            "--shard {shard}: {} shards but the {} configurations come from only {} scene file{} (all configurations of a scene run in one shard): N must be at most {}",
            shard.count,
            configs.len(),
            scenes.len(),
            if scenes.len() == 1 { "" } else { "s" },
            scenes.len()
        ));
    }
    let mut order: Vec<usize> = (0..scenes.len()).collect();
    order.sort_by(|&a, &b| scenes[b].1.cmp(&scenes[a].1).then(a.cmp(&b)));
    let mut load = vec![0usize; shard.count];
    let mut owner = vec![0usize; scenes.len()];
    for i in order {
        let (s, _) = load
            .iter()
            .enumerate()
            .min_by_key(|&(k, l)| (*l, k))
            .unwrap_or((0, &0));
        owner[i] = s;
        load[s] += scenes[i].1;
    }
    Ok(configs
        .iter()
        .filter(|c| {
            scene_index
                .get(c.scene_path.as_path())
                .is_some_and(|&i| owner[i] == shard.index - 1)
        })
        .cloned()
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::test_util::config;

    #[test]
    fn shards_partition_every_configuration_once_keeping_scenes_together() {
        let mut configs = Vec::new();
        for (scene, n) in [("a", 5), ("b", 1), ("c", 3), ("d", 3), ("e", 2), ("f", 7)] {
            for i in 0..n {
                configs.push(config(scene, &format!("sdf:{i}")));
            }
        }
        for count in 1..=6 {
            let shards: Vec<Vec<Config>> = (1..=count)
                .map(|index| shard(&configs, Shard { index, count }).unwrap())
                .collect();
            let mut seen: Vec<&str> = shards.iter().flatten().map(|c| c.id.as_str()).collect();
            seen.sort_unstable();
            let mut all: Vec<&str> = configs.iter().map(|c| c.id.as_str()).collect();
            all.sort_unstable();
            assert_eq!(seen, all, "{count} shards");
            for s in &shards {
                for c in s {
                    // A scene lives in exactly one shard.
                    assert_eq!(
                        shards
                            .iter()
                            .filter(|t| t.iter().any(|d| d.scene == c.scene))
                            .count(),
                        1
                    );
                }
                // Suite order kept.
                let pos: Vec<usize> = s
                    .iter()
                    .map(|c| configs.iter().position(|d| d.id == c.id).unwrap_or(0))
                    .collect();
                assert!(pos.windows(2).all(|w| w[0] < w[1]));
            }
            // Deterministic.
            assert_eq!(
                shard(&configs, Shard { index: 1, count }).unwrap(),
                shards[0]
            );
        }
        // Two shards balance 21 configurations as 11 / 10 (f+b+e... greedily).
        let two: Vec<usize> = (1..=2)
            .map(|index| shard(&configs, Shard { index, count: 2 }).unwrap().len())
            .collect();
        assert_eq!(two.iter().sum::<usize>(), 21);
        assert!(two.iter().all(|&n| (10..=11).contains(&n)), "{two:?}");
        // Six scenes: a seventh shard would be empty.
        let e = shard(&configs, Shard { index: 7, count: 7 }).unwrap_err();
        assert!(e.contains("at most 6"), "{e}");
    }

    #[test]
    fn one_scene_file_is_named_in_the_singular() {
        let configs = vec![config("a", "sdf"), config("a", "mesh")];
        let e = shard(&configs, Shard { index: 1, count: 2 }).unwrap_err();
        assert!(
            e.contains("only 1 scene file (") && e.contains("at most 1"),
            "{e}"
        );
    }

    #[test]
    fn more_shards_than_scenes_are_refused_before_allocating() {
        let configs = vec![config("a", "sdf"), config("b", "sdf")];
        for count in [3, 1_000_000_000_000, usize::MAX] {
            let e = shard(&configs, Shard { index: 1, count }).unwrap_err();
            assert!(e.contains("at most 2"), "{e}");
        }
        assert_eq!(
            shard(&configs, Shard { index: 2, count: 2 }).unwrap().len(),
            1
        );
    }

    #[test]
    fn shard_specs_parse_and_refuse_nonsense() {
        assert_eq!("2/8".parse::<Shard>(), Ok(Shard { index: 2, count: 8 }));
        for bad in ["0/3", "4/3", "3", "a/b", "1/0", ""] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }
}
