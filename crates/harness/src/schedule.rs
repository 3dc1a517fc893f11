//! The interleaved rotation schedule of a benchmark run: after every configuration of a
//! rotation group (one scene and resolution) is built and warmed up, their timed repeats are
//! taken in rounds (A B C, then e.g. C A B, ...), each round's order shuffled by a seeded
//! generator recorded in the results, so slow drifts of the machine's load fall on every
//! configuration alike and per-round ratios cancel them.

/// SplitMix64 (Steele, Lea and Flood, "Fast splittable pseudorandom number generators",
/// OOPSLA 2014): a tiny, well-mixed generator; the same seed always gives the same order.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform integer in `0..n` (`n >= 1`; Lemire's multiply-shift, bias below 2^-32 for
    /// the small `n` of a schedule).
    pub fn below(&mut self, n: usize) -> usize {
        ((u128::from(self.next_u64()) * n as u128) >> 64) as usize
    }

    /// Shuffles `items` in place (Fisher-Yates).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = self.below(i + 1);
            items.swap(i, j);
        }
    }
}

/// The seed of round `round` of rotation group `group` in a run seeded with `run_seed`: each
/// round's order is reproducible on its own.
pub fn round_seed(run_seed: u64, group: &str, round: u32) -> u64 {
    // FNV-1a of the group name, mixed with the run seed and round.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in group.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    SplitMix64::new(run_seed ^ h ^ u64::from(round).wrapping_mul(0xA24B_AED4_963E_E407)).next_u64()
}

/// The order of round `round`: the indices of `active` (the members still wanting repeats)
/// shuffled with [`round_seed`].
pub fn round_order(active: &[usize], run_seed: u64, group: &str, round: u32) -> Vec<usize> {
    let mut order = active.to_vec();
    SplitMix64::new(round_seed(run_seed, group, round)).shuffle(&mut order);
    order
}

/// A run seed from the clock (recorded in the results; pass `--seed` to reproduce an order).
pub fn clock_seed() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0x5EED, |d| d.as_nanos() as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed rotation: every member in every round, each round shuffled.
    fn rotation(members: usize, rounds: u32, run_seed: u64, group: &str) -> Vec<Vec<usize>> {
        let all: Vec<usize> = (0..members).collect();
        (0..rounds)
            .map(|r| round_order(&all, run_seed, group, r))
            .collect()
    }

    #[test]
    fn every_configuration_gets_every_round_and_the_seed_reproduces_the_order() {
        let s = rotation(5, 12, 42, "g/scene/64x64");
        assert_eq!(s.len(), 12);
        for round in &s {
            let mut sorted = round.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, vec![0, 1, 2, 3, 4], "{round:?}");
        }
        // Same seed and group: the same order; another seed or group: another order.
        assert_eq!(s, rotation(5, 12, 42, "g/scene/64x64"));
        assert_ne!(s, rotation(5, 12, 43, "g/scene/64x64"));
        assert_ne!(s, rotation(5, 12, 42, "g/other/64x64"));
        // The order really is shuffled: not every round starts with the same member, and
        // each member leads some round over enough rounds.
        let leaders: std::collections::BTreeSet<usize> =
            rotation(3, 40, 7, "g").iter().map(|r| r[0]).collect();
        assert_eq!(leaders.len(), 3, "{leaders:?}");
    }

    #[test]
    fn shuffles_are_uniform_enough() {
        // Each of the 6 permutations of 3 items appears 1/6 of the time (within 5 sigma).
        let mut counts = std::collections::HashMap::new();
        let mut g = SplitMix64::new(1);
        let n = 60_000;
        for _ in 0..n {
            let mut v = [0, 1, 2];
            g.shuffle(&mut v);
            *counts.entry(v).or_insert(0usize) += 1;
        }
        assert_eq!(counts.len(), 6);
        let expect = n as f64 / 6.0;
        let sigma = (expect * 5.0 / 6.0).sqrt();
        for (p, c) in counts {
            assert!((c as f64 - expect).abs() < 5.0 * sigma, "{p:?}: {c}");
        }
    }

    #[test]
    fn round_order_keeps_only_active_members() {
        let o = round_order(&[1, 4, 6], 9, "g", 3);
        let mut s = o.clone();
        s.sort_unstable();
        assert_eq!(s, vec![1, 4, 6]);
    }
}
