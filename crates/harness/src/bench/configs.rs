//! A suite's configurations: expanded from the suite and the options, filtered, named, and
//! grouped into rotation blocks.

use std::path::Path;

use marchmesh_scene::RenderOverrides;

use super::{BenchOptions, Config};
use crate::stats::RepeatPolicy;
use crate::suite::{BackendConfig, Resolution, Suite, glob_match};

/// A scene path as results record it, the same on every machine: from the nearest folder
/// named `scenes` on (`scenes/csg.json`, wherever the checkout or the extracted built-in copy
/// is), else relative to the current folder when below it, else as given; `..` and `.`
/// resolved lexically, `/`-separated.
pub fn portable_scene_path(path: &Path) -> String {
    use std::path::Component;
    let mut parts: Vec<String> = Vec::new();
    let mut absolute = false;
    for c in path.components() {
        match c {
            Component::ParentDir => {
                if parts.pop().is_none() && !absolute {
                    parts.push("..".into());
                }
            }
            Component::CurDir => {}
            Component::RootDir | Component::Prefix(_) => absolute = true,
            Component::Normal(n) => parts.push(n.to_string_lossy().into_owned()),
        }
    }
    if let Some(i) = parts.iter().rposition(|p| p == "scenes") {
        return parts[i..].join("/");
    }
    if absolute
        && let Ok(cwd) = std::env::current_dir()
        && let Ok(rel) = Path::new(&format!("/{}", parts.join("/"))).strip_prefix(&cwd)
    {
        return rel.to_string_lossy().replace('\\', "/");
    }
    let joined = parts.join("/");
    if absolute {
        format!("/{joined}")
    } else {
        joined
    }
}

pub(super) fn resolve_threads(t: usize) -> usize {
    if t == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        t
    }
}

pub(super) fn resolution_tag(r: Resolution) -> String {
    match r {
        Resolution::Size { width, height } => format!("{width}x{height}"),
        Resolution::MaxSide { max_side } => format!("max{max_side}"),
        Resolution::Scale { scale } => format!("x{scale}"),
    }
}

/// Whether `id` passes `filter`.
pub fn filter_matches(filter: &str, id: &str) -> bool {
    if filter.contains(['*', '?']) {
        glob_match(filter, id)
    } else {
        id.contains(filter)
    }
}

/// The configurations of `suite` under `options` (filter applied), in run order.
pub fn configurations(suite: &Suite, options: &BenchOptions) -> Vec<Config> {
    let mut out = Vec::new();
    for g in &suite.groups {
        let threads: Vec<usize> = match options.threads {
            Some(t) => vec![resolve_threads(t)],
            None => g.threads.iter().map(|&t| resolve_threads(t)).collect(),
        };
        let base = g.repeats.unwrap_or(suite.repeats);
        let repeats = if options.quick {
            suite.quick_repeats.min_repeats_of(base)
        } else {
            base
        };
        for (scene, path) in &g.scenes {
            for &resolution in &g.resolutions {
                for BackendConfig {
                    label,
                    spec,
                    render,
                } in &g.backends
                {
                    for &t in &threads {
                        let kind = spec.kind.name();
                        let id = format!(
                            "{}/{scene}/{kind}:{label}/{}/t{t}",
                            g.name,
                            resolution_tag(resolution)
                        );
                        if options
                            .filter
                            .as_deref()
                            .is_some_and(|f| !filter_matches(f, &id))
                        {
                            continue;
                        }
                        out.push(Config {
                            id,
                            group: g.name.clone(),
                            scene: scene.clone(),
                            scene_path: path.clone(),
                            label: label.clone(),
                            spec: spec.clone(),
                            resolution,
                            render: RenderOverrides {
                                samples_per_pixel: render.samples_per_pixel.or(g.spp),
                                ..render.clone()
                            },
                            truth_render: RenderOverrides {
                                samples_per_pixel: g.truth.samples_per_pixel.or(g.spp),
                                ..g.truth.clone()
                            },
                            threads: t,
                            reference: g.reference,
                            repeats,
                        });
                    }
                }
            }
        }
    }
    out
}

impl RepeatPolicy {
    /// The quick policy, but never more repeats than `base` asks for.
    pub(super) fn min_repeats_of(self, base: RepeatPolicy) -> RepeatPolicy {
        RepeatPolicy {
            min_count: self.min_count.min(base.min_count).max(1),
            min_time_s: self.min_time_s.min(base.min_time_s),
            max_count: self.max_count.min(base.max_count).max(1),
        }
    }
}

/// The longest [`slug`] in bytes: two of them plus the longest prefix and suffix the tools
/// add (`steps_histogram_`, `_`, `_accuracy.svg`) stay well under the 255-byte file-name
/// limit of common file systems.
pub const SLUG_MAX_BYTES: usize = 96;

/// File-name-safe version of a configuration id (or a group, scene or suite name): ASCII
/// letters, digits and `-_.=` kept, anything else `_`. At most [`SLUG_MAX_BYTES`] bytes: a
/// longer one keeps a readable prefix and ends in `-` and 16 hex digits of a stable hash
/// (FNV-1a) of the whole `id`, so distinct long ids keep distinct names.
pub fn slug(id: &str) -> String {
    let full: String = id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.=".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if full.len() <= SLUG_MAX_BYTES {
        return full;
    }
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in id.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    // `full` is ASCII, so any byte index is a character boundary.
    format!("{}-{h:016x}", &full[..SLUG_MAX_BYTES - 17])
}

/// Consecutive runs of `configs` measured in one rotation: same suite group, scene file,
/// resolution and render settings (they differ in backend, quality and threads).
pub fn rotation_blocks(configs: &[Config]) -> Vec<std::ops::Range<usize>> {
    let key = |c: &Config| {
        (
            c.group.clone(),
            c.scene_path.clone(),
            resolution_tag(c.resolution),
        )
    };
    let mut blocks: Vec<std::ops::Range<usize>> = Vec::new();
    for (i, c) in configs.iter().enumerate() {
        match blocks.last_mut() {
            Some(b) if key(&configs[b.start]) == key(c) => b.end = i + 1,
            _ => blocks.push(i..i + 1),
        }
    }
    blocks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::test_util::config;

    #[test]
    fn long_slugs_are_capped_with_a_stable_hash() {
        assert_eq!(slug("g/s/sdf:a b/x1/t1"), "g_s_sdf_a_b_x1_t1");
        let long = |c: char| format!("{}/s/sdf:a/x1/t1", c.to_string().repeat(300));
        let (a, b) = (slug(&long('a')), slug(&long('b')));
        assert_eq!(a.len(), SLUG_MAX_BYTES);
        assert!(a.starts_with("aaaa") && a != b, "{a} {b}");
        assert_eq!(a, slug(&long('a')));
        // Ids differing only past the prefix still differ.
        let (x, y) = (
            format!("{}x", "g".repeat(200)),
            format!("{}y", "g".repeat(200)),
        );
        assert_ne!(slug(&x), slug(&y));
    }

    #[test]
    fn results_record_scene_paths_from_the_scenes_folder() {
        assert_eq!(
            portable_scene_path(Path::new("/work/main/scenes/suites/../csg.json")),
            "scenes/csg.json"
        );
        assert_eq!(
            portable_scene_path(Path::new(
                "/home/u/.cache/marchmesh/0.1-ab/scenes/meshes/../seed-spheres.json"
            )),
            "scenes/seed-spheres.json"
        );
        assert_eq!(
            portable_scene_path(Path::new("mine/./x.json")),
            "mine/x.json"
        );
        assert_eq!(
            portable_scene_path(Path::new("/elsewhere/x.json")),
            "/elsewhere/x.json"
        );
    }

    #[test]
    fn rotation_blocks_group_one_scene_and_resolution() {
        let mut c = vec![config("a", "sdf"), config("a", "mesh"), config("b", "sdf")];
        c[1].resolution = Resolution::Size {
            width: 64,
            height: 64,
        };
        let mut d = config("a", "mesh:2");
        d.resolution = Resolution::MaxSide { max_side: 32 };
        c.push(d);
        assert_eq!(rotation_blocks(&c), vec![0..2, 2..3, 3..4]);
    }
}
