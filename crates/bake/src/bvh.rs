//! A small f32 binary BVH over triangles for two queries: the closest triangle to a point
//! (exact, branch-and-bound) and the fast generalized winding number (Barill et al. 2018,
//! first-order "dipole" far field).

use glam::Vec3;

use crate::geom::{point_triangle_distance_squared, solid_angle};

/// Triangles per leaf at most.
const LEAF: usize = 4;
/// Far-field acceptance: a cluster is replaced by its dipole when the query point is more
/// than `BETA` times the cluster radius from its centre (Barill et al. use 2 with a
/// second-order expansion; the first-order one here takes a little more).
pub(crate) const BETA: f32 = 2.5;
const STACK: usize = 64;

#[derive(Debug, Clone, Copy)]
struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Leaf: first triangle; inner: left child (right = first + 1).
    first: u32,
    /// Triangles in a leaf; 0 for an inner node.
    count: u32,
}

/// Winding-number moments of one node's triangles.
#[derive(Debug, Clone, Copy)]
struct Moment {
    /// Area-weighted centroid.
    c: Vec3,
    /// Radius around `c` enclosing every triangle of the node.
    r: f32,
    /// Sum of area vectors (half the cross products), the dipole moment.
    n: Vec3,
}

/// The BVH; triangles are stored by value in leaf order.
pub(crate) struct Bvh {
    nodes: Vec<Node>,
    moments: Vec<Moment>,
    tris: Vec<[Vec3; 3]>,
}

fn box_dist2(p: Vec3, lo: Vec3, hi: Vec3) -> f32 {
    let d = (lo - p).max(p - hi).max(Vec3::ZERO);
    d.length_squared()
}

impl Bvh {
    /// Builds over `tris` (median split on the longest centroid axis).
    pub fn build(tris: Vec<[Vec3; 3]>) -> Bvh {
        let n = tris.len();
        let cent: Vec<Vec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let mut order: Vec<u32> = (0..n as u32).collect();
        let mut nodes = Vec::with_capacity(2 * n / LEAF + 2);
        nodes.push(Node {
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
            first: 0,
            count: 0,
        });
        if n > 0 {
            Self::split(&mut nodes, 0, &mut order, 0, &tris, &cent);
        }
        let tris: Vec<[Vec3; 3]> = order.iter().map(|&i| tris[i as usize]).collect();
        let mut bvh = Bvh {
            nodes,
            moments: Vec::new(),
            tris,
        };
        if !bvh.tris.is_empty() {
            bvh.compute_moments();
        }
        bvh
    }

    fn split(
        nodes: &mut Vec<Node>,
        node: usize,
        order: &mut [u32],
        start: usize,
        tris: &[[Vec3; 3]],
        cent: &[Vec3],
    ) {
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        let (mut clo, mut chi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for &i in order.iter() {
            for v in tris[i as usize] {
                lo = lo.min(v);
                hi = hi.max(v);
            }
            clo = clo.min(cent[i as usize]);
            chi = chi.max(cent[i as usize]);
        }
        nodes[node].lo = lo;
        nodes[node].hi = hi;
        if order.len() <= LEAF {
            nodes[node].first = start as u32;
            nodes[node].count = order.len() as u32;
            return;
        }
        let ext = chi - clo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&a, &b| {
            cent[a as usize][axis].total_cmp(&cent[b as usize][axis])
        });
        let left = nodes.len();
        let blank = nodes[node];
        nodes.push(blank);
        nodes.push(blank);
        nodes[node].first = left as u32;
        nodes[node].count = 0;
        let (l, r) = order.split_at_mut(mid);
        Self::split(nodes, left, l, start, tris, cent);
        Self::split(nodes, left + 1, r, start + mid, tris, cent);
    }

    fn compute_moments(&mut self) {
        // Children come after parents, so a reverse sweep sees children first. Every node's
        // triangles are a contiguous range of `tris` (leaf order).
        let mut area = vec![0.0f32; self.nodes.len()];
        let mut range = vec![(0u32, 0u32); self.nodes.len()];
        self.moments = vec![
            Moment {
                c: Vec3::ZERO,
                r: 0.0,
                n: Vec3::ZERO,
            };
            self.nodes.len()
        ];
        for i in (0..self.nodes.len()).rev() {
            let nd = self.nodes[i];
            let (mut a_sum, mut c_sum, mut n_sum) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
            if nd.count > 0 {
                range[i] = (nd.first, nd.first + nd.count);
                for t in &self.tris[nd.first as usize..(nd.first + nd.count) as usize] {
                    let av = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]);
                    let a = av.length();
                    a_sum += a;
                    c_sum += a * (t[0] + t[1] + t[2]) / 3.0;
                    n_sum += av;
                }
            } else {
                let (l, r) = (nd.first as usize, nd.first as usize + 1);
                range[i] = (range[l].0.min(range[r].0), range[l].1.max(range[r].1));
                for k in [l, r] {
                    a_sum += area[k];
                    c_sum += area[k] * self.moments[k].c;
                    n_sum += self.moments[k].n;
                }
            }
            let c = if a_sum > 0.0 && (c_sum / a_sum).is_finite() {
                c_sum / a_sum
            } else {
                0.5 * (nd.lo + nd.hi)
            };
            // Exact enclosing radius around c: the farthest vertex of the node's triangles
            // (a little slack for round-off).
            let r2 = self.tris[range[i].0 as usize..range[i].1 as usize]
                .iter()
                .flat_map(|t| t.iter())
                .map(|v| (*v - c).length_squared())
                .fold(0.0f32, f32::max);
            area[i] = a_sum;
            self.moments[i] = Moment {
                c,
                r: r2.sqrt() * (1.0 + 1e-5),
                n: n_sum,
            };
        }
    }

    /// Exact bytes held (lengths, not capacities).
    pub fn memory_bytes(&self) -> u64 {
        (self.nodes.len() * std::mem::size_of::<Node>()
            + self.moments.len() * std::mem::size_of::<Moment>()
            + self.tris.len() * std::mem::size_of::<[Vec3; 3]>()) as u64
    }

    /// Closest triangle to `p`: `(squared distance, triangle index)`. `hint` (a triangle
    /// index, e.g. the neighbouring sample's answer) seeds the bound. Returns
    /// `(INFINITY, u32::MAX)` for an empty BVH.
    pub fn closest(&self, p: Vec3, hint: u32) -> (f32, u32) {
        let mut best = (f32::INFINITY, u32::MAX);
        if let Some(t) = self.tris.get(hint as usize) {
            best = (point_triangle_distance_squared(p, t[0], t[1], t[2]), hint);
        }
        if self.tris.is_empty() {
            return best;
        }
        let mut stack = [(0u32, 0.0f32); STACK];
        let mut sp = 0;
        let root = &self.nodes[0];
        stack[0] = (0, box_dist2(p, root.lo, root.hi));
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let (ni, d2) = stack[sp];
            if d2 >= best.0 {
                continue;
            }
            let nd = &self.nodes[ni as usize];
            if nd.count > 0 {
                for k in nd.first..nd.first + nd.count {
                    let t = &self.tris[k as usize];
                    let d = point_triangle_distance_squared(p, t[0], t[1], t[2]);
                    if d < best.0 {
                        best = (d, k);
                    }
                }
            } else {
                let (l, r) = (nd.first, nd.first + 1);
                let ln = &self.nodes[l as usize];
                let rn = &self.nodes[r as usize];
                let dl = box_dist2(p, ln.lo, ln.hi);
                let dr = box_dist2(p, rn.lo, rn.hi);
                // Push the farther first so the nearer is popped next.
                let (a, b) = if dl <= dr {
                    ((r, dr), (l, dl))
                } else {
                    ((l, dl), (r, dr))
                };
                for e in [a, b] {
                    if e.1 < best.0 && sp < STACK {
                        stack[sp] = e;
                        sp += 1;
                    }
                }
            }
        }
        best
    }

    /// Every triangle within `radius` of `c`: `(distance to c, triangle index)`, unsorted.
    /// Gives up (returns false, `out` incomplete) once more than `limit` are found.
    pub fn gather(&self, c: Vec3, radius: f32, limit: usize, out: &mut Vec<(f32, u32)>) -> bool {
        out.clear();
        if self.tris.is_empty() {
            return true;
        }
        let r2 = radius * radius;
        let mut stack = [0u32; STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let nd = &self.nodes[stack[sp] as usize];
            if box_dist2(c, nd.lo, nd.hi) > r2 {
                continue;
            }
            if nd.count > 0 {
                for k in nd.first..nd.first + nd.count {
                    let t = &self.tris[k as usize];
                    let d2 = point_triangle_distance_squared(c, t[0], t[1], t[2]);
                    if d2 <= r2 {
                        out.push((d2.sqrt(), k));
                    }
                }
                if out.len() > limit {
                    return false;
                }
            } else if sp + 2 <= STACK {
                stack[sp] = nd.first;
                stack[sp + 1] = nd.first + 1;
                sp += 2;
            }
        }
        true
    }

    /// Triangle `k` (leaf order).
    #[inline]
    pub fn tri(&self, k: u32) -> &[Vec3; 3] {
        &self.tris[k as usize]
    }

    /// Generalized winding number at `p` (Jacobson et al. 2013): the sum of signed solid
    /// angles over `4pi`; 1 inside a closed outward mesh, 0 outside, fractional near holes.
    /// Clusters farther than `BETA` radii use their dipole term (Barill et al. 2018).
    pub fn winding(&self, p: Vec3) -> f32 {
        if self.tris.is_empty() {
            return 0.0;
        }
        let mut sum = 0.0f32;
        let mut stack = [0u32; STACK];
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let ni = stack[sp] as usize;
            let m = &self.moments[ni];
            let d = m.c - p;
            let dist2 = d.length_squared();
            if dist2 > (BETA * m.r) * (BETA * m.r) {
                sum += m.n.dot(d) / (dist2 * dist2.sqrt());
                continue;
            }
            let nd = &self.nodes[ni];
            if nd.count > 0 {
                for t in &self.tris[nd.first as usize..(nd.first + nd.count) as usize] {
                    sum += solid_angle(p, t[0], t[1], t[2]);
                }
            } else if sp + 2 <= STACK {
                stack[sp] = nd.first;
                stack[sp + 1] = nd.first + 1;
                sp += 2;
            }
        }
        sum / (4.0 * std::f32::consts::PI)
    }

    /// Exact generalized winding number (every triangle; O(n)), for tests.
    #[cfg(test)]
    pub fn winding_exact(&self, p: Vec3) -> f32 {
        let s: f64 = self
            .tris
            .iter()
            .map(|t| solid_angle(p, t[0], t[1], t[2]) as f64)
            .sum();
        (s / (4.0 * std::f64::consts::PI)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed, outward-oriented UV sphere (radius 1) with `n` segments.
    fn sphere(n: usize) -> Vec<[Vec3; 3]> {
        let at = |i: usize, j: usize| {
            let th = std::f32::consts::PI * i as f32 / n as f32;
            let ph = 2.0 * std::f32::consts::PI * j as f32 / n as f32;
            Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
        };
        let mut t = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                if i + 1 != n {
                    t.push([a, c, b]);
                }
                if i != 0 {
                    t.push([a, d, c]);
                }
            }
        }
        t
    }

    #[test]
    fn closest_matches_brute_force() {
        let tris = sphere(24);
        let bvh = Bvh::build(tris.clone());
        for k in 0..200 {
            let f = k as f32;
            let p = Vec3::new((f * 0.37).sin(), (f * 0.71).cos(), (f * 0.13).sin()) * 1.7;
            let brute = tris
                .iter()
                .map(|t| point_triangle_distance_squared(p, t[0], t[1], t[2]))
                .fold(f32::INFINITY, f32::min);
            let (d2, i) = bvh.closest(p, (k * 7) as u32);
            assert_eq!(d2, brute, "{p}");
            let t = bvh.tris[i as usize];
            assert_eq!(point_triangle_distance_squared(p, t[0], t[1], t[2]), d2);
        }
    }

    #[test]
    fn fast_winding_close_to_exact() {
        let bvh = Bvh::build(sphere(32));
        let mut worst = 0.0f32;
        for k in 0..300 {
            let f = k as f32;
            let p = Vec3::new((f * 0.37).sin(), (f * 0.71).cos(), (f * 0.13).sin()) * 1.5;
            let (fast, exact) = (bvh.winding(p), bvh.winding_exact(p));
            worst = worst.max((fast - exact).abs());
            let expect = if p.length() < 0.99 { 1.0 } else { 0.0 };
            if (p.length() - 1.0).abs() > 0.02 {
                assert!((exact - expect).abs() < 0.01, "{p} {exact}");
            }
        }
        assert!(worst < 0.02, "worst fast-vs-exact winding error {worst}");
    }

    #[test]
    fn empty_bvh() {
        let bvh = Bvh::build(Vec::new());
        assert_eq!(bvh.closest(Vec3::ONE, 0).0, f32::INFINITY);
        assert_eq!(bvh.winding(Vec3::ONE), 0.0);
    }
}
