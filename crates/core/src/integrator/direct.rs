//! The hit pass of a scene whose shading points spawn no secondary rays (no shadows, area
//! lights or ambient occlusion): each surface hit's colour is its ambient term plus Phong
//! over the point and directional lights, with the material and lights converted once per
//! render, in a loop of its own. The same operations in the same order as the Whitted
//! integrator's general hit loop, so the same bits; a hit it does not take (a reflecting
//! surface, a non-finite hit) is left to that loop.

use glam::Vec3;

use super::band::Band;
use super::shading::{DirectLight, Shading, phong};
use super::whitted::Path;
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

/// Shades the hits `hits` (wavefront indices of results that hold a hit) in order, adding
/// each one's colour to its pixel's `sum` (and recording its AOVs when its index is below
/// `w.aov_paths`), and stops at the first hit the general loop must take: one whose hit is
/// not finite or whose surface reflects. Returns how many hits it shaded.
///
/// With `distinct` (no two paths of the wavefront share a pixel: one sample a pixel) and
/// AVX, hits are shaded eight at a time, each lane the scalar operations in their order.
///
/// Only for a [`Shading`] that spawns nothing (`sh.spawns` false).
///
/// # Panics
/// If an index is outside the wavefront or a pixel outside `sum` (a programming error).
#[inline(never)]
pub(super) fn shade_direct(
    hits: &[u32],
    w: &Wavefront<'_>,
    sum: &mut [Vec3],
    band: &mut Band<'_>,
    sh: &Shading,
    distinct: bool,
) -> usize {
    debug_assert!(
        !sh.spawns,
        "the direct pass shades scenes that spawn nothing"
    );
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if distinct && std::arch::is_x86_feature_detected!("avx") {
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
            lanes.scatter(w, sum, band);
            done += LANES;
        }
    }
    done + shade_scalar(&hits[done..], w, sum, band, sh)
}

/// [`shade_direct`] one hit at a time.
#[inline(always)]
fn shade_scalar(
    hits: &[u32],
    w: &Wavefront<'_>,
    sum: &mut [Vec3],
    band: &mut Band<'_>,
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
        let mut s = sum[px] + weight * sh.ambient * color;
        for light in &sh.direct {
            let (to_light, intensity) = match *light {
                DirectLight::Point {
                    position,
                    intensity,
                } => {
                    let v = position - hit.position;
                    let to_light = v / v.length();
                    if !to_light.is_finite() {
                        continue;
                    }
                    (to_light, intensity)
                }
                DirectLight::Directional {
                    to_light,
                    intensity,
                } => (to_light, intensity),
            };
            let amount = phong(n, d, to_light, intensity, m.specular_exponent);
            if amount <= 0.0 {
                continue;
            }
            s += weight * amount * color;
        }
        sum[px] = s;
    }
    hits.len()
}

/// Hits shaded together by [`shade_lanes_avx`].
const LANES: usize = 8;

/// Eight hits as structure of arrays: what shading reads of each (gathered from the
/// wavefront), and the colour sums and facing normals it leaves.
#[derive(Default)]
struct Lanes {
    /// Wavefront index of each lane's hit.
    index: [usize; LANES],
    /// Band pixel of each lane.
    pixel: [usize; LANES],
    /// The hit's normal as traced; the facing unit normal after shading.
    normal: [[f32; LANES]; 3],
    dir: [[f32; LANES]; 3],
    position: [[f32; LANES]; 3],
    weight: [f32; LANES],
    color: [[f32; LANES]; 3],
    /// Specular exponent, for lanes with a bit in `specular_lanes`.
    specular: [f32; LANES],
    specular_lanes: u8,
    /// The pixel's colour sum before shading; after, with the hit's colour added.
    sum: [[f32; LANES]; 3],
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
            for c in 0..3 {
                l.normal[c][i] = hit.normal[c];
                l.dir[c][i] = ray.dir[c];
                l.position[c][i] = hit.position[c];
                l.color[c][i] = m.color[c];
                l.sum[c][i] = s[c];
            }
            if let Some(e) = m.specular_exponent {
                l.specular[i] = e;
                l.specular_lanes |= 1 << i;
            }
        }
        true
    }

    /// Writes each lane's colour sum into `sum` and, below `w.aov_paths`, its AOVs.
    #[inline(always)]
    fn scatter(&self, w: &Wavefront<'_>, sum: &mut [Vec3], band: &mut Band<'_>) {
        let [sr, sg, sb] = &self.sum;
        let [nx, ny, nz] = &self.normal;
        for i in 0..LANES {
            sum[self.pixel[i]] = Vec3::new(sr[i], sg[i], sb[i]);
            if self.index[i] < w.aov_paths {
                let res = &w.results[self.index[i]];
                if let Some(hit) = res.hit() {
                    let n = Vec3::new(nx[i], ny[i], nz[i]);
                    band.set_aov(self.pixel[i], res, Some((&hit, n)));
                }
            }
        }
    }
}

/// [`shade_scalar`]'s arithmetic for eight hits in AVX lanes: every lane performs the
/// scalar code's IEEE operations in the same order (correctly rounded in any lane width, no
/// fused multiply-add), comparisons by the same ordered or unordered predicates and
/// `powf` per lane, so each lane's sum and normal are the scalar code's bits.
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
    let d = l.dir.each_ref().map(load);
    let weight = load(&l.weight);
    let color = l.color.each_ref().map(load);
    // `normalize_or_zero`: `v * (1 / sqrt(v.v))` where that reciprocal is finite and
    // positive, else zero; then turned to face the ray (`-v` where `v.d > 0`).
    let v = l.normal.each_ref().map(load);
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
    let mut s: [__m256; 3] =
        std::array::from_fn(|c| _mm256_add_ps(load(&l.sum[c]), _mm256_mul_ps(aw, color[c])));
    let neg_d = d.map(|c| _mm256_xor_ps(c, sign));
    let position = l.position.each_ref().map(load);
    let all = _mm256_cmp_ps::<_CMP_EQ_OQ>(zero, zero);
    for light in &sh.direct {
        let (to_light, intensity, valid) = match *light {
            DirectLight::Point {
                position: at,
                intensity,
            } => {
                let v: [__m256; 3] =
                    std::array::from_fn(|c| _mm256_sub_ps(_mm256_set1_ps(at[c]), position[c]));
                let len = _mm256_sqrt_ps(dot(v, v));
                let t = v.map(|c| _mm256_div_ps(c, len));
                let valid = _mm256_and_ps(_mm256_and_ps(finite(t[0]), finite(t[1])), finite(t[2]));
                (t, intensity, valid)
            }
            DirectLight::Directional {
                to_light,
                intensity,
            } => (
                std::array::from_fn(|c| _mm256_set1_ps(to_light[c])),
                intensity,
                all,
            ),
        };
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
        let add = _mm256_and_ps(lit, _mm256_cmp_ps::<_CMP_NLE_UQ>(amount, zero));
        let wa = _mm256_mul_ps(weight, amount);
        s = std::array::from_fn(|c| {
            _mm256_blendv_ps(s[c], _mm256_add_ps(s[c], _mm256_mul_ps(wa, color[c])), add)
        });
    }
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
    use super::super::whitted::Path;
    use super::{Wavefront, shade_direct};
    use crate::framebuffer::Framebuffer;
    use crate::geometry::{Hit, Ray, RayWork, TraceResult};
    use crate::sampling::Rng;

    /// Eight hits a time shade the bits of one at a time, on hits built to reach every
    /// branch: zero, tiny, huge and back-facing normals, a hit at a point light's position
    /// (no direction to it), specular and plain materials, weights below one.
    #[test]
    fn lanes_shade_the_bits_of_single_hits() {
        let scene = marchmesh_scene::parse_scene(
            r#"{
              "camera": {"width": 40, "height": 8},
              "lights": [{"ambient": {"intensity": 0.2}},
                         {"point": {"position": [0.5, 0.5, 3], "intensity": 0.7, "casts_shadows": false}},
                         {"directional": {"direction": [0.2, 1, -1], "intensity": 0.4, "casts_shadows": false}}],
              "objects": [
                {"shape": {"sphere": {"radius": 1}}, "material": {"color": [0.9, 0.5, 0.1], "specular_exponent": 7}},
                {"shape": {"sphere": {"radius": 1}}, "material": {"color": [0.2, 0.6, 0.8]}}
              ]
            }"#,
            "lanes",
            std::path::Path::new("."),
        )
        .expect("scene");
        let sh = Shading::new(&scene);
        assert!(!sh.spawns && sh.direct.len() == 2);
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
            {
                let mut bands = Band::split(&mut fb, 8, true);
                let done = shade_direct(&hits, &w, &mut sum, &mut bands[0], &sh, distinct);
                assert_eq!(done, hits.len());
            }
            (sum, fb)
        };
        let ((a, fa), (b, fb)) = (shade(true), shade(false));
        let bits = |v: &[Vec3]| -> Vec<[u32; 3]> {
            v.iter().map(|c| c.to_array().map(f32::to_bits)).collect()
        };
        assert_eq!(bits(&a), bits(&b));
        assert_eq!(bits(&fa.normal), bits(&fb.normal));
        assert_eq!(fa.depth, fb.depth);
        assert_eq!(fa.material, fb.material);
    }
}
