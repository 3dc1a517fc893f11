//! The hit pass of a scene whose lights are point, directional and ambient lights, without
//! ambient occlusion: each surface hit's colour is its ambient term plus Phong over the point
//! and directional lights, with the material and lights converted once per render, in a loop
//! of its own; a light that casts shadows queues its shadow ray and contribution instead of
//! adding it. The same operations in the same order as the Whitted integrator's general hit
//! loop, and the same shadow rays in the same order, so the same bits; a hit it does not take
//! (a reflecting surface, a non-finite hit) is left to that loop.

use glam::{Vec3, Vec3A};

use super::band::Band;
use super::shading::{DirectLight, Shading, phong};
use super::whitted::{Path, PendingLight};
use crate::geometry::{Ray, TraceResult};

/// One wavefront as the direct pass reads it: its paths, rays and results (one per path),
/// the index of its rays below which hits record AOVs (0 for none), and the depth.
pub(super) struct Wavefront<'a> {
    pub(super) paths: &'a [Path],
    pub(super) rays: &'a [Ray],
    pub(super) results: &'a [TraceResult],
    pub(super) aov_paths: usize,
    pub(super) depth: u32,
}

/// The wavefront's queue of shadow rays and, at the same index, their pending contributions
/// (added to their path's pixel if the ray is not blocked).
pub(super) struct Shadows<'a> {
    pub(super) rays: &'a mut Vec<Ray>,
    pub(super) pending: &'a mut Vec<PendingLight>,
}

impl<'a> Shadows<'a> {
    /// The queue held in `rays` and `pending`.
    #[inline(always)]
    pub(super) fn of(rays: &'a mut Vec<Ray>, pending: &'a mut Vec<PendingLight>) -> Self {
        Shadows { rays, pending }
    }

    /// Queues a shadow ray from `origin` towards `dir` up to `t_max` for path `path`.
    #[inline(always)]
    pub(super) fn push(&mut self, path: usize, origin: Vec3, dir: Vec3, t_max: f32, amount: Vec3) {
        self.rays.push(Ray {
            origin,
            dir,
            t_min: 0.0,
            t_max,
        });
        self.pending.push(PendingLight {
            path: path as u32,
            amount,
        });
    }
}

/// Shades the hits `hits` (wavefront indices of results that hold a hit) in order, adding
/// each one's colour to its pixel's `sum` (and recording its AOVs when its index is below
/// `w.aov_paths`), and stops at the first hit the general loop must take: one whose hit is
/// not finite or whose surface reflects. Returns how many hits it shaded. A light that casts
/// shadows queues its ray and contribution in `shadows` (hit by hit, light by light, as the
/// general loop does) unless the light is at or behind the ray's start; the rest is added.
///
/// With `distinct` (no two paths of the wavefront share a pixel: one sample a pixel) and
/// AVX, hits are shaded eight at a time, each lane the scalar operations in their order.
///
/// Only for a [`Shading`] with `sh.direct_pass`.
///
/// # Panics
/// If an index is outside the wavefront or a pixel outside `sum` (a programming error).
#[inline(never)]
pub(super) fn shade_direct(
    hits: &[u32],
    w: &Wavefront<'_>,
    sum: &mut [Vec3],
    band: &mut Band<'_>,
    mut shadows: Shadows<'_>,
    sh: &Shading,
    distinct: bool,
) -> usize {
    debug_assert!(
        sh.direct_pass,
        "the direct pass shades scenes of point, directional and ambient lights"
    );
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if distinct
        && sh.direct.iter().filter(|l| l.shadows()).count() <= MAX_QUEUED
        && std::arch::is_x86_feature_detected!("avx")
    {
        let mut lanes = Lanes::default();
        while let Some(group) = hits.get(done..done + LANES) {
            if !lanes.gather(group, w, sum, sh) {
                break;
            }
            // SAFETY: the CPU reports AVX (checked above).
            #[allow(unsafe_code)]
            unsafe {
                shade_lanes_avx(&mut lanes, sh)
            };
            lanes.scatter(w, sum, band, &mut shadows);
            done += LANES;
        }
    }
    done + shade_scalar(&hits[done..], w, sum, band, &mut shadows, sh)
}

/// [`shade_direct`] one hit at a time.
#[inline(always)]
fn shade_scalar(
    hits: &[u32],
    w: &Wavefront<'_>,
    sum: &mut [Vec3],
    band: &mut Band<'_>,
    shadows: &mut Shadows<'_>,
    sh: &Shading,
) -> usize {
    let Wavefront {
        paths,
        rays,
        results,
        aov_paths,
        depth,
    } = *w;
    for (k, &pi) in hits.iter().enumerate() {
        let pi = pi as usize;
        let (path, ray, res) = (&paths[pi], &rays[pi], &results[pi]);
        let Some(hit) = res.hit() else {
            return k;
        };
        if !(hit.t.is_finite() && hit.position.is_finite() && hit.normal.is_finite()) {
            return k;
        }
        let m = sh.surface(hit.material);
        let refl = m.reflectivity;
        if refl > 0.0 && depth < sh.max_depth && path.throughput * refl > sh.cutoff {
            return k;
        }
        let mut n = hit.normal.normalize_or_zero();
        if n.dot(ray.dir) > 0.0 {
            n = -n;
        }
        let px = path.pixel as usize;
        if pi < aov_paths {
            band.set_aov(px, res, Some((&hit, n)));
        }
        let (weight, color, d) = (path.throughput, m.color, ray.dir);
        // Where shadow rays start (`spawns`: some light casts shadows), as the general loop
        // places them.
        let (offset, origin) = if sh.spawns {
            let offset = sh.ray_offset * hit.position.length().max(1e-30);
            (offset, hit.position + n * offset)
        } else {
            (0.0, hit.position)
        };
        let mut s = sum[px] + weight * sh.ambient * color;
        for light in &sh.direct {
            let (to_light, intensity, shadowed, dist) = match *light {
                DirectLight::Point {
                    position,
                    intensity,
                    shadows,
                } => {
                    let v = position - hit.position;
                    let len = v.length();
                    let to_light = v / len;
                    if !to_light.is_finite() {
                        continue;
                    }
                    (to_light, intensity, shadows, len - offset)
                }
                DirectLight::Directional {
                    to_light,
                    intensity,
                    shadows,
                } => (to_light, intensity, shadows, sh.max_distance),
            };
            let amount = phong(n, d, to_light, intensity, m.specular_exponent);
            if amount <= 0.0 {
                continue;
            }
            let contribution = weight * amount * color;
            if shadowed && dist > 0.0 {
                shadows.push(pi, origin, to_light, dist, contribution);
            } else {
                s += contribution;
            }
        }
        sum[px] = s;
    }
    hits.len()
}

/// Hits shaded together by [`shade_lanes_avx`].
const LANES: usize = 8;

/// Most lights casting shadows the lanes queue rays for (a scene with more is shaded one hit
/// at a time).
const MAX_QUEUED: usize = 4;

/// One shadowed light's rays of eight lanes: which lanes queue one, and each lane's
/// direction, length and pending contribution.
#[derive(Default)]
struct Queued {
    lanes: u8,
    dir: [[f32; LANES]; 3],
    dist: [f32; LANES],
    amount: [[f32; LANES]; 3],
}

/// Eight hits: what shading reads of each, gathered from the wavefront one vector a lane
/// (one 16-byte store each, turned into structure of arrays in registers by
/// [`shade_lanes_avx`]), and the colour sums and facing normals it leaves as structure of
/// arrays.
#[derive(Default)]
struct Lanes {
    /// Wavefront index of each lane's hit.
    index: [usize; LANES],
    /// Band pixel of each lane.
    pixel: [usize; LANES],
    /// The hit's normal as traced, a lane each.
    traced_normal: [Vec3A; LANES],
    dir: [Vec3A; LANES],
    position: [Vec3A; LANES],
    color: [Vec3A; LANES],
    /// The pixel's colour sum before shading, a lane each.
    sum_before: [Vec3A; LANES],
    /// The facing unit normal after shading.
    normal: [[f32; LANES]; 3],
    weight: [f32; LANES],
    /// Specular exponent, for lanes with a bit in `specular_lanes`.
    specular: [f32; LANES],
    specular_lanes: u8,
    /// After shading, the pixel's colour sum with the hit's colour added (but for the
    /// contributions queued behind shadow rays).
    sum: [[f32; LANES]; 3],
    /// Where the hit's shadow rays start (set when a light casts shadows).
    origin: [[f32; LANES]; 3],
    /// The shadow rays of the first `queued_lights` lights that cast shadows, in their order.
    queued: [Queued; MAX_QUEUED],
    queued_lights: usize,
}

impl Lanes {
    /// Gathers the hits `group` (eight wavefront indices); false if any of them is one the
    /// general loop takes (as [`shade_scalar`] decides), the lanes then partly overwritten.
    #[inline(always)]
    fn gather(&mut self, group: &[u32], w: &Wavefront<'_>, sum: &[Vec3], sh: &Shading) -> bool {
        let l = self;
        l.specular_lanes = 0;
        for (i, &pi) in group.iter().enumerate().take(LANES) {
            let pi = pi as usize;
            let (path, ray, res) = (&w.paths[pi], &w.rays[pi], &w.results[pi]);
            let Some(hit) = res.hit() else {
                return false;
            };
            if !(hit.t.is_finite() && hit.position.is_finite() && hit.normal.is_finite()) {
                return false;
            }
            let m = sh.surface(hit.material);
            let refl = m.reflectivity;
            if refl > 0.0 && w.depth < sh.max_depth && path.throughput * refl > sh.cutoff {
                return false;
            }
            let px = path.pixel as usize;
            let s = sum[px];
            (l.index[i], l.pixel[i], l.weight[i]) = (pi, px, path.throughput);
            l.traced_normal[i] = hit.normal.into();
            l.dir[i] = ray.dir.into();
            l.position[i] = hit.position.into();
            l.color[i] = m.color.into();
            l.sum_before[i] = s.into();
            if let Some(e) = m.specular_exponent {
                l.specular[i] = e;
                l.specular_lanes |= 1 << i;
            }
        }
        true
    }

    /// Writes each lane's colour sum into `sum` and, below `w.aov_paths`, its AOVs, and
    /// queues its shadow rays, lane by lane and light by light.
    #[inline(always)]
    fn scatter(
        &self,
        w: &Wavefront<'_>,
        sum: &mut [Vec3],
        band: &mut Band<'_>,
        shadows: &mut Shadows<'_>,
    ) {
        let [sr, sg, sb] = &self.sum;
        let [nx, ny, nz] = &self.normal;
        let [ox, oy, oz] = &self.origin;
        let queued = &self.queued[..self.queued_lights];
        for i in 0..LANES {
            sum[self.pixel[i]] = Vec3::new(sr[i], sg[i], sb[i]);
            if self.index[i] < w.aov_paths {
                let res = &w.results[self.index[i]];
                if let Some(hit) = res.hit() {
                    let n = Vec3::new(nx[i], ny[i], nz[i]);
                    band.set_aov(self.pixel[i], res, Some((&hit, n)));
                }
            }
            for q in queued {
                if q.lanes >> i & 1 == 1 {
                    let [dx, dy, dz] = &q.dir;
                    let [ar, ag, ab] = &q.amount;
                    shadows.push(
                        self.index[i],
                        Vec3::new(ox[i], oy[i], oz[i]),
                        Vec3::new(dx[i], dy[i], dz[i]),
                        q.dist[i],
                        Vec3::new(ar[i], ag[i], ab[i]),
                    );
                }
            }
        }
    }
}

/// [`shade_scalar`]'s arithmetic for eight hits in AVX lanes: every lane performs the
/// scalar code's IEEE operations in the same order (correctly rounded in any lane width, no
/// fused multiply-add), comparisons by the same ordered or unordered predicates and
/// `powf` per lane, so each lane's sum, normal and shadow rays are the scalar code's bits.
/// At most [`MAX_QUEUED`] lights may cast shadows.
///
/// # Panics
/// If more lights cast shadows (a programming error).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[allow(unsafe_code)]
fn shade_lanes_avx(l: &mut Lanes, sh: &Shading) {
    use std::arch::x86_64::*;
    // SAFETY: each load reads the 8 f32 of a `[f32; 8]`.
    let load = |a: &[f32; LANES]| unsafe { _mm256_loadu_ps(a.as_ptr()) };
    let store = |a: &mut [f32; LANES], v: __m256| {
        // SAFETY: each store writes the 8 f32 of a `[f32; 8]`.
        unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) }
    };
    let dot = |a: [__m256; 3], b: [__m256; 3]| {
        _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(a[0], b[0]), _mm256_mul_ps(a[1], b[1])),
            _mm256_mul_ps(a[2], b[2]),
        )
    };
    let (zero, one, inf) = (
        _mm256_setzero_ps(),
        _mm256_set1_ps(1.0),
        _mm256_set1_ps(f32::INFINITY),
    );
    let sign = _mm256_set1_ps(-0.0);
    // `x.is_finite()` per lane: |x| < infinity (false for NaN).
    let finite = |x: __m256| _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_andnot_ps(sign, x), inf);
    // Eight lanes' (x, y, z, _) vectors as three vectors of x, y and z: lanes 0-3 in the low
    // halves, 4-7 in the high ones, transposed 4 x 4 in each half.
    let soa = |a: &[Vec3A; LANES]| -> [__m256; 3] {
        let v: [__m256; 4] =
            std::array::from_fn(|i| _mm256_set_m128(__m128::from(a[i + 4]), __m128::from(a[i])));
        let lo01 = _mm256_unpacklo_ps(v[0], v[1]);
        let lo23 = _mm256_unpacklo_ps(v[2], v[3]);
        let hi01 = _mm256_unpackhi_ps(v[0], v[1]);
        let hi23 = _mm256_unpackhi_ps(v[2], v[3]);
        [
            _mm256_shuffle_ps::<0b01_00_01_00>(lo01, lo23),
            _mm256_shuffle_ps::<0b11_10_11_10>(lo01, lo23),
            _mm256_shuffle_ps::<0b01_00_01_00>(hi01, hi23),
        ]
    };
    let d = soa(&l.dir);
    let weight = load(&l.weight);
    let color = soa(&l.color);
    // `normalize_or_zero`: `v * (1 / sqrt(v.v))` where that reciprocal is finite and
    // positive, else zero; then turned to face the ray (`-v` where `v.d > 0`).
    let v = soa(&l.traced_normal);
    let rcp = _mm256_div_ps(one, _mm256_sqrt_ps(dot(v, v)));
    let ok = _mm256_and_ps(
        _mm256_cmp_ps::<_CMP_GT_OQ>(rcp, zero),
        _mm256_cmp_ps::<_CMP_LT_OQ>(rcp, inf),
    );
    let n = v.map(|c| _mm256_and_ps(_mm256_mul_ps(c, rcp), ok));
    let flip = _mm256_and_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(dot(n, d), zero), sign);
    let n = n.map(|c| _mm256_xor_ps(c, flip));
    // Ambient: `sum + weight * ambient * colour`.
    let aw = _mm256_mul_ps(weight, _mm256_set1_ps(sh.ambient));
    let sum = soa(&l.sum_before);
    let mut s: [__m256; 3] =
        std::array::from_fn(|c| _mm256_add_ps(sum[c], _mm256_mul_ps(aw, color[c])));
    let neg_d = d.map(|c| _mm256_xor_ps(c, sign));
    let position = soa(&l.position);
    // Shadow rays' start: `offset = ray_offset * max(|p|, 1e-30)` (`max` returns its second
    // operand for a NaN first, as `f32::max` does), `origin = p + n * offset`.
    let offset = if sh.spawns {
        let len = _mm256_sqrt_ps(dot(position, position));
        let offset = _mm256_mul_ps(
            _mm256_set1_ps(sh.ray_offset),
            _mm256_max_ps(len, _mm256_set1_ps(1e-30)),
        );
        for c in 0..3 {
            store(
                &mut l.origin[c],
                _mm256_add_ps(position[c], _mm256_mul_ps(n[c], offset)),
            );
        }
        offset
    } else {
        zero
    };
    let all = _mm256_cmp_ps::<_CMP_EQ_OQ>(zero, zero);
    let mut queued = 0;
    for light in &sh.direct {
        let (to_light, intensity, shadows, dist) = match *light {
            DirectLight::Point {
                position: at,
                intensity,
                shadows,
            } => {
                let v: [__m256; 3] =
                    std::array::from_fn(|c| _mm256_sub_ps(_mm256_set1_ps(at[c]), position[c]));
                let len = _mm256_sqrt_ps(dot(v, v));
                let t = v.map(|c| _mm256_div_ps(c, len));
                let valid = _mm256_and_ps(_mm256_and_ps(finite(t[0]), finite(t[1])), finite(t[2]));
                ((t, valid), intensity, shadows, _mm256_sub_ps(len, offset))
            }
            DirectLight::Directional {
                to_light,
                intensity,
                shadows,
            } => (
                (std::array::from_fn(|c| _mm256_set1_ps(to_light[c])), all),
                intensity,
                shadows,
                _mm256_set1_ps(sh.max_distance),
            ),
        };
        let (to_light, valid) = to_light;
        // `phong`: zero unless `n.l > 0`, else `intensity * n.l` plus the specular term.
        let ndl = dot(n, to_light);
        let lit = _mm256_and_ps(valid, _mm256_cmp_ps::<_CMP_GT_OQ>(ndl, zero));
        let mut amount = _mm256_mul_ps(_mm256_set1_ps(intensity), ndl);
        let specular = l.specular_lanes & _mm256_movemask_ps(lit) as u8;
        if specular != 0 {
            let two = _mm256_set1_ps(2.0);
            let r: [__m256; 3] = std::array::from_fn(|c| {
                _mm256_sub_ps(_mm256_mul_ps(_mm256_mul_ps(two, n[c]), ndl), to_light[c])
            });
            let (mut rv, mut a) = ([0.0; LANES], [0.0; LANES]);
            store(&mut rv, dot(r, neg_d));
            store(&mut a, amount);
            for i in 0..LANES {
                if specular >> i & 1 == 1 && rv[i] > 0.0 {
                    a[i] += intensity * rv[i].powf(l.specular[i]);
                }
            }
            amount = load(&a);
        }
        // Added unless `amount <= 0` (a NaN amount is added, as in the scalar code).
        let mut add = _mm256_and_ps(lit, _mm256_cmp_ps::<_CMP_NLE_UQ>(amount, zero));
        let wa = _mm256_mul_ps(weight, amount);
        let contribution: [__m256; 3] = std::array::from_fn(|c| _mm256_mul_ps(wa, color[c]));
        if shadows {
            // Queued behind a shadow ray where `dist > 0`, added where not.
            let queue = _mm256_and_ps(add, _mm256_cmp_ps::<_CMP_GT_OQ>(dist, zero));
            add = _mm256_andnot_ps(queue, add);
            let q = &mut l.queued[queued];
            q.lanes = _mm256_movemask_ps(queue) as u8;
            store(&mut q.dist, dist);
            for c in 0..3 {
                store(&mut q.dir[c], to_light[c]);
                store(&mut q.amount[c], contribution[c]);
            }
            queued += 1;
        }
        s = std::array::from_fn(|c| {
            _mm256_blendv_ps(s[c], _mm256_add_ps(s[c], contribution[c]), add)
        });
    }
    l.queued_lights = queued;
    for c in 0..3 {
        store(&mut l.sum[c], s[c]);
        store(&mut l.normal[c], n[c]);
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::super::band::Band;
    use super::super::shading::Shading;
    use super::super::whitted::{Path, PendingLight};
    use super::{Shadows, Wavefront, shade_direct};
    use crate::framebuffer::Framebuffer;
    use crate::geometry::{Hit, Ray, RayWork, TraceResult};
    use crate::sampling::Rng;

    /// Eight hits a time shade the bits of one at a time, and queue the same shadow rays in
    /// the same order, on hits built to reach every branch: zero, tiny, huge and back-facing
    /// normals, a hit at a point light's position (no direction to it), specular and plain
    /// materials, weights below one; lights with and without shadows.
    #[test]
    fn lanes_shade_the_bits_of_single_hits() {
        for shadows in [false, true] {
            lanes_match_single_hits(shadows);
        }
    }

    fn lanes_match_single_hits(shadows: bool) {
        let json = r#"{
              "camera": {"width": 40, "height": 8},
              "lights": [{"ambient": {"intensity": 0.2}},
                         {"point": {"position": [0.5, 0.5, 3], "intensity": 0.7, "casts_shadows": SHADOWS}},
                         {"directional": {"direction": [0.2, 1, -1], "intensity": 0.4, "casts_shadows": SHADOWS}},
                         {"point": {"position": [-2, 1, 2], "intensity": 0.3, "casts_shadows": false}}],
              "objects": [
                {"shape": {"sphere": {"radius": 1}}, "material": {"color": [0.9, 0.5, 0.1], "specular_exponent": 7}},
                {"shape": {"sphere": {"radius": 1}}, "material": {"color": [0.2, 0.6, 0.8]}}
              ]
            }"#
        .replace("SHADOWS", &shadows.to_string());
        let scene =
            marchmesh_scene::parse_scene(&json, "lanes", std::path::Path::new(".")).expect("scene");
        let sh = Shading::new(&scene);
        assert!(sh.direct_pass && sh.spawns == shadows && sh.direct.len() == 3);
        let light = Vec3::new(0.5, 0.5, 3.0);
        let mut rng = Rng::new(7);
        let mut u = move || rng.next_f32() * 2.0 - 1.0;
        let n = 320;
        let (mut paths, mut rays, mut results) = (vec![], vec![], vec![]);
        for i in 0..n {
            let dir = Vec3::new(u(), u(), 1.0).normalize();
            let position = if i % 29 == 3 {
                light
            } else {
                Vec3::new(u(), u(), 3.0 + u())
            };
            let normal = match i % 11 {
                0 => Vec3::ZERO,
                1 => Vec3::splat(1e-30),
                2 => Vec3::splat(3e38),
                3 => dir,
                _ => Vec3::new(u(), u(), u()),
            };
            paths.push(Path {
                pixel: i,
                sample: 0,
                throughput: if i % 3 == 0 { 1.0 } else { u().abs() },
            });
            rays.push(Ray {
                origin: Vec3::ZERO,
                dir,
                t_min: 0.0,
                t_max: 100.0,
            });
            results.push(TraceResult::found(
                Hit {
                    t: 3.0,
                    position,
                    normal,
                    material: (i % 3 == 0) as u32 + 1,
                },
                RayWork::default(),
            ));
        }
        let hits: Vec<u32> = (0..n).collect();
        let w = Wavefront {
            paths: &paths,
            rays: &rays,
            results: &results,
            aov_paths: n as usize,
            depth: 0,
        };
        let shade = |distinct: bool| {
            let mut fb = Framebuffer::new(40, 8);
            let mut sum = vec![Vec3::splat(0.25); n as usize];
            let (mut rays, mut pending): (Vec<Ray>, Vec<PendingLight>) = (vec![], vec![]);
            {
                let mut bands = Band::split(&mut fb, 8, true);
                let shadows = Shadows {
                    rays: &mut rays,
                    pending: &mut pending,
                };
                let done = shade_direct(&hits, &w, &mut sum, &mut bands[0], shadows, &sh, distinct);
                assert_eq!(done, hits.len());
            }
            (sum, fb, rays, pending)
        };
        let ((a, fa, ra, pa), (b, fb, rb, pb)) = (shade(true), shade(false));
        let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
            v.iter().map(|c| c.to_array().map(f32::to_bits)).collect()
        };
        assert_eq!(bits(&a), bits(&b));
        let ray_bits = |r: &[Ray]| -> Vec<[u32; 8]> {
            r.iter()
                .map(|r| {
                    let [ox, oy, oz] = r.origin.to_array().map(f32::to_bits);
                    let [dx, dy, dz] = r.dir.to_array().map(f32::to_bits);
                    [ox, oy, oz, dx, dy, dz, r.t_min.to_bits(), r.t_max.to_bits()]
                })
                .collect()
        };
        assert_eq!(ray_bits(&ra), ray_bits(&rb));
        assert_eq!(
            pa.iter().map(|p| p.path).collect::<Vec<_>>(),
            pb.iter().map(|p| p.path).collect::<Vec<_>>()
        );
        let amounts = |p: &[PendingLight]| bits(&p.iter().map(|p| p.amount).collect::<Vec<_>>());
        assert_eq!(amounts(&pa), amounts(&pb));
        assert_eq!(ra.len(), pa.len());
        // Rays only from lights that cast shadows: some from each of them.
        let directional = ra.iter().filter(|r| r.t_max == sh.max_distance).count();
        assert_eq!(directional > 0, shadows);
        assert_eq!(ra.len() > directional, shadows);
        assert_eq!(bits(&fa.normal), bits(&fb.normal));
        assert_eq!(fa.depth, fb.depth);
        assert_eq!(fa.material, fb.material);
    }
}
