//! The distance field's one-query approximations: soft shadows from one march along a cone's
//! axis and ambient occlusion from a few field taps along the normal.
//!
//! Both read only the field's distances, 8 queries per 8-lane evaluation, and are the
//! shortcuts distance-field renderers use for "free" soft shadows and AO (Unreal's
//! distance-field shadows and AO follow the same ideas). The harness measures their error
//! against the sampled answer; they are approximations, not estimators that converge.

use marchmesh_core::{Cone, RayWork, SurfacePoint, Termination, Visibility};
use marchmesh_field::Field;

/// Unblocked fraction of each cone from one march along its axis, by the penumbra estimate
/// of Quilez ("Soft shadows in raymarched SDFs", 2010; the smooth `-1..1` variant of 2020):
/// `r = min over the march of d(t) / (t tan(half angle))`, visibility
/// `(1 + r)^2 (2 - r) / 4` with `r` clamped to `[-1, 1]` (0 where the axis is blocked deeply
/// enough that the whole cone is, 1/2 where it grazes an occluder, 1 when nothing comes
/// within the cone). Steps are the field distance, at least 1/1000 of the cone length, at
/// most `max_steps` per cone; a cone that runs out of steps reports `MaxSteps` and its
/// estimate so far.
pub(crate) fn cone_visibility(
    field: &Field,
    cones: &[Cone],
    out: &mut [Visibility],
    max_steps: u32,
) {
    assert_eq!(cones.len(), out.len(), "cone_visibility: lengths differ");
    for (chunk, res) in cones.chunks(8).zip(out.chunks_mut(8)) {
        let n = chunk.len();
        let mut t = [0.0f32; 8];
        let mut ratio = [1.0f32; 8];
        let mut done = [true; 8];
        let mut steps = [0u32; 8];
        let mut term = [Termination::MaxDistance; 8];
        for (i, c) in chunk.iter().enumerate() {
            done[i] = !(c.t_max > 0.0 && c.tan_half_angle > 0.0);
        }
        while done[..n].iter().any(|d| !d) {
            let mut p = [glam::Vec3::ZERO; 8];
            for i in 0..n {
                if !done[i] {
                    p[i] = chunk[i].origin + chunk[i].dir * t[i];
                }
            }
            let d = field.distance_x8(p);
            for i in 0..n {
                if done[i] {
                    continue;
                }
                let c = &chunk[i];
                steps[i] += 1;
                let min_step = c.t_max * 1e-3;
                // At t = 0 the apex sits on its own surface: only later samples bound the cone.
                if t[i] > 0.0 {
                    ratio[i] = ratio[i].min(d[i] / (c.tan_half_angle * t[i]));
                }
                t[i] += d[i].max(min_step);
                if ratio[i] <= -1.0 {
                    term[i] = Termination::Hit;
                    done[i] = true;
                } else if t[i] >= c.t_max {
                    term[i] = Termination::MaxDistance;
                    done[i] = true;
                } else if steps[i] >= max_steps {
                    term[i] = Termination::MaxSteps;
                    done[i] = true;
                }
            }
        }
        for i in 0..n {
            let r = ratio[i].clamp(-1.0, 1.0);
            res[i] = Visibility {
                fraction: 0.25 * (1.0 + r) * (1.0 + r) * (2.0 - r),
                termination: term[i],
                work: RayWork {
                    steps: steps[i],
                    ..RayWork::default()
                },
            };
        }
    }
}

/// Open fraction of each point's hemisphere within `distance` from `taps` field samples
/// along the normal at heights `h_k = distance k / taps` (Evans, "Fast Approximations for
/// Global Illumination on Dynamic Scenes", SIGGRAPH 2006 course): a sample closer to a
/// surface than its height, `d_k < h_k`, is occluded by `(h_k - d_k) / h_k`; samples are
/// weighted `2^-k` (near ones count most) and the result is `1 - weighted mean`. An open
/// plane gives exactly 1.
pub(crate) fn ambient_openness(
    field: &Field,
    taps: u32,
    points: &[SurfacePoint],
    distance: f32,
    out: &mut [Visibility],
) {
    assert_eq!(points.len(), out.len(), "ambient_openness: lengths differ");
    let taps = taps.max(1);
    let weight_sum: f32 = (1..=taps).map(|k| 0.5f32.powi(k as i32)).sum();
    // Flatten (point, tap) pairs and evaluate them 8 at a time.
    let total = points.len() * taps as usize;
    let mut occlusion = vec![0.0f32; points.len()];
    let mut pair = 0;
    while pair < total {
        let count = (total - pair).min(8);
        let mut p = [glam::Vec3::ZERO; 8];
        let mut h = [0.0f32; 8];
        for (lane, (pl, hl)) in p.iter_mut().zip(h.iter_mut()).enumerate().take(count) {
            let (point, k) = (
                (pair + lane) / taps as usize,
                (pair + lane) % taps as usize + 1,
            );
            *hl = distance * k as f32 / taps as f32;
            *pl = points[point].position + points[point].normal * *hl;
        }
        let d = field.distance_x8(p);
        for lane in 0..count {
            let (point, k) = (
                (pair + lane) / taps as usize,
                (pair + lane) % taps as usize + 1,
            );
            let blocked = ((h[lane] - d[lane]) / h[lane]).clamp(0.0, 1.0);
            occlusion[point] += 0.5f32.powi(k as i32) * blocked;
        }
        pair += count;
    }
    for (o, occ) in out.iter_mut().zip(occlusion) {
        *o = Visibility {
            fraction: (1.0 - occ / weight_sum).clamp(0.0, 1.0),
            termination: Termination::Hit,
            work: RayWork {
                steps: taps,
                ..RayWork::default()
            },
        };
    }
}
