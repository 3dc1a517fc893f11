//! Beam starts: one cone march for a group of neighbouring camera rays before they march
//! on their own.
//!
//! Camera rays of neighbouring pixels cross the same empty space before they reach a
//! surface, and sphere tracing pays that crossing once per ray. A *beam* marches the cone
//! around a group of [`BEAM_RAYS`] rays sharing an origin instead: from the axis point
//! `a(t) = o + t * axis`, every ray's point at the same distance `t` lies within `k * t`,
//! with `k = max |dir_i - axis|` over the group's unit directions, so when the field there
//! is `d`, each ray's points on `[t, t + d - k t - m]` lie within `d - m` of `a(t)`, hence at
//! least `m` from every surface. The beam steps by `c = d - k t - m` while that gains more
//! than `m`, and every ray of the group then starts where its beam stopped
//! ([`crate::march::March::advance_start`]). Real-time sphere tracers call this cone
//! marching; it is Hart's unbounding-sphere step ("Sphere Tracing", The Visual Computer
//! 1996) taken for a cone of rays (Amanatides, "Ray Tracing with Cones", SIGGRAPH 1984):
//! the step of the axis less the cone's radius.
//!
//! `m`, twice the hit shell at the point plus the rounding level of positions, keeps every
//! ray out of the shell before its start, so no near-miss decision is skipped; a field that
//! is no strict bound (mesh grids) may still let a beam overshoot, which the ray notices at
//! its first sample and undoes. Eight beams march in the lanes of one 8-lane evaluation.

use glam::Vec3;
use marchmesh_core::Ray;
use marchmesh_field::{F32x8, Lane, V3};

use crate::march::{March, Params};

/// Consecutive rays of a batch sharing one beam: a run of four pixels of an image row (or
/// of a screen tile's row), narrow enough that its cone stops within a few pixel
/// footprints of the first surface.
pub(crate) const BEAM_RAYS: usize = 4;

/// Most cone steps per beam: a beam skimming a surface converges geometrically and is cut
/// off here (its rays then march on from wherever it got).
pub(crate) const BEAM_STEPS: u32 = 24;

/// The beams of a batch stop together once no more than this many still advance: each
/// cone step evaluates all eight lanes, and beams that stopped leave theirs idle. Measured: `docs/decisions/0013`.
pub(crate) const BEAM_MIN_ACTIVE: usize = 4;

/// Rays per call of [`advance_by_beams`]: the groups of eight beams, one per lane.
pub(crate) const BEAM_BATCH: usize = 8 * BEAM_RAYS;

/// One beam: the group's rays' common origin, unit axis, spread `k`, and the range of
/// distances along the axis its rays march over.
#[derive(Debug, Clone, Copy)]
struct Beam {
    origin: Vec3,
    axis: Vec3,
    spread: f32,
    t_near: f32,
    t_far: f32,
}

impl Beam {
    /// The beam around `marches` (the group's rays, `None` for rays with nothing to march),
    /// or `None` when no ray of the group marches, their origins differ, or a direction is
    /// not finite.
    fn around(marches: &[Option<March>]) -> Option<Beam> {
        let mut units = [Vec3::ZERO; BEAM_RAYS];
        let mut n = 0;
        let (mut origin, mut sum) = (None, Vec3::ZERO);
        let (mut t_near, mut t_far) = (f32::INFINITY, 0.0f32);
        for m in marches.iter().flatten() {
            let o = *origin.get_or_insert(m.origin());
            let len = m.dir().length();
            if m.origin() != o || !(len > 0.0 && len.is_finite()) {
                return None;
            }
            let unit = m.dir() / len;
            sum += unit;
            units[n] = unit;
            n += 1;
            let (t, t_end) = m.range();
            t_near = t_near.min(t * len);
            t_far = t_far.max(t_end * len);
        }
        let axis = sum.try_normalize()?;
        let spread = units[..n]
            .iter()
            .map(|&u| (u - axis).length_squared())
            .fold(0.0f32, f32::max)
            .sqrt();
        // A little wider, for the rounding of the directions and of the ray points.
        let spread = spread * (1.0 + 1e-4) + 1e-6;
        (t_far.is_finite() && t_near <= t_far).then_some(Beam {
            origin: origin?,
            axis,
            spread,
            t_near,
            t_far,
        })
    }
}

/// Marches the beams of `marches` (consecutive groups of [`BEAM_RAYS`], at most
/// [`BEAM_BATCH`] rays, `None` for rays with nothing to march) through `distance`, the
/// 8-lane field the rays are then traced through, and advances each ray's start to where
/// its beam stopped. Rays whose beam gains nothing are left as they are.
pub(crate) fn advance_by_beams(
    marches: &mut [Option<March>],
    p: &Params,
    distance: impl Fn(V3<F32x8>) -> F32x8,
) {
    debug_assert!(marches.len() <= BEAM_BATCH);
    let c = F32x8::splat;
    let mut beams: [Option<Beam>; 8] = [None; 8];
    for (beam, group) in beams.iter_mut().zip(marches.chunks(BEAM_RAYS)) {
        *beam = Beam::around(group);
    }
    let lane =
        |f: &dyn Fn(&Beam) -> f32| F32x8(std::array::from_fn(|k| beams[k].as_ref().map_or(0.0, f)));
    let (o, axis) = (
        V3 {
            x: lane(&|b| b.origin.x),
            y: lane(&|b| b.origin.y),
            z: lane(&|b| b.origin.z),
        },
        V3 {
            x: lane(&|b| b.axis.x),
            y: lane(&|b| b.axis.y),
            z: lane(&|b| b.axis.z),
        },
    );
    let spread = lane(&|b| b.spread);
    let t_far = lane(&|b| b.t_far);
    let base = lane(&|b| b.origin.length());
    let mut t = lane(&|b| b.t_near);
    let mut active = F32x8::lt(c(0.0), lane(&|_| 1.0));
    let mut moved = [false; 8];
    let mut steps = [0u32; 8];
    for _ in 0..BEAM_STEPS {
        if active.0.iter().filter(|&&a| a != 0).count() <= BEAM_MIN_ACTIVE {
            break;
        }
        let active_before = active;
        let d = distance(V3 {
            x: o.x + axis.x * t,
            y: o.y + axis.y * t,
            z: o.z + axis.z * t,
        });
        // Twice the shell (`March::eps`) plus eight times the rounding level of positions.
        let path = base + t;
        let margin = c(2.0) * (c(p.eps_abs) + c(p.eps_cone) * path) + c(8.0 * 2.4e-7) * path;
        let gain = d - spread * t - margin;
        // `margin < gain` is false for NaN: such a beam stops.
        let advance = F32x8::and(active, F32x8::lt(margin, gain));
        t = F32x8::select(advance, (t + gain).min(t_far), t);
        active = F32x8::and(advance, F32x8::lt(t, t_far));
        for k in 0..8 {
            moved[k] |= advance.0[k] != 0;
            steps[k] += u32::from(active_before.0[k] != 0);
        }
    }
    for (k, group) in marches.chunks_mut(BEAM_RAYS).enumerate() {
        // The beam's evaluations are charged to its first ray, so the rays' work adds up.
        if let Some(m) = group.iter_mut().flatten().next() {
            m.charge_shared(steps[k]);
        }
        if !moved[k] {
            continue;
        }
        for m in group.iter_mut().flatten() {
            let len = m.dir().length();
            m.advance_start(t.0[k] / len);
        }
    }
}

/// Whether `rays` get beams: they share an origin (camera rays), make at least one full
/// group, and the origin lies in the scene's box. From outside the box the rays are
/// clipped to start next to what it bounds, with little empty space left to skip, while
/// preparing the beams still costs its set-up: on the fidget anchor's 1 and 10 spheres seen
/// from outside their box (1.7 and 3.5 evaluations a ray) beams made camera rays 15% and 8%
/// slower, and seed-slab 7%.
pub(crate) fn worth_it(rays: &[Ray], p: &Params) -> bool {
    let Some(first) = rays.first() else {
        return false;
    };
    let o = first.origin;
    rays.len() >= BEAM_RAYS
        && p.bounds
            .is_none_or(|(lo, hi)| o.cmpge(lo).all() && o.cmple(hi).all())
        && rays.iter().all(|r| r.origin == o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::march::Next;
    use marchmesh_core::Termination;

    fn params() -> Params {
        Params {
            eps_abs: 1e-4,
            eps_cone: 0.0,
            omega: 1.2,
            max_steps: 512,
            refine_steps: 16,
            max_distance: 100.0,
            bounds: None,
            segment: false,
            segment_sweeps: false,
            recede_checks: false,
        }
    }

    fn ray(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir: dir.normalize(),
            t_min: 0.0,
            t_max: 100.0,
        }
    }

    /// A unit sphere at z = 5.
    fn sphere(p: Vec3) -> f32 {
        (p - Vec3::new(0.0, 0.0, 5.0)).length() - 1.0
    }

    fn lanes(f: impl Fn(Vec3) -> f32) -> impl Fn(V3<F32x8>) -> F32x8 {
        move |p: V3<F32x8>| {
            F32x8(std::array::from_fn(|k| {
                f(Vec3::new(p.x.0[k], p.y.0[k], p.z.0[k]))
            }))
        }
    }

    /// Marches `m` through `f` to the end: `(termination, t, own evaluations)`.
    fn run(mut m: March, p: &Params, f: impl Fn(Vec3) -> f32) -> (Termination, f32, u32) {
        loop {
            if let Next::Done(term) = m.feed(f(m.point()), p) {
                return (term, m.t, m.evals);
            }
        }
    }

    fn marches(p: &Params) -> Vec<Option<March>> {
        (0..BEAM_BATCH)
            .map(|i| {
                let x = (i as f32 - 16.0) * 0.01;
                March::new(&ray(Vec3::ZERO, Vec3::new(x, 0.02, 1.0)), p, true).ok()
            })
            .collect()
    }

    #[test]
    fn beams_advance_rays_without_changing_their_hits() {
        let p = params();
        let plain = marches(&p);
        let mut beamed = plain.clone();
        advance_by_beams(&mut beamed, &p, lanes(sphere));
        let mut saved = 0;
        for (a, b) in plain.iter().zip(&beamed) {
            let (a, b) = (a.unwrap(), b.unwrap());
            let (ta, tb) = (a.range().0, b.range().0);
            // Every beamed start is clear of the sphere by at least two shells.
            assert!(
                tb > ta && sphere(b.point()) >= 2.0 * p.eps_abs,
                "start {tb}"
            );
            let (ra, rb) = (run(a, &p, sphere), run(b, &p, sphere));
            assert_eq!(ra.0, Termination::Hit);
            assert_eq!(ra.0, rb.0);
            assert!((ra.1 - rb.1).abs() <= 1e-5 * ra.1, "t {} vs {}", ra.1, rb.1);
            saved += i64::from(ra.2) - i64::from(rb.2);
        }
        assert!(saved > BEAM_BATCH as i64, "beams saved {saved} evaluations");
    }

    #[test]
    fn a_beam_that_overshoots_restarts_its_rays() {
        // A field that is no bound (it claims 1 unit more than the distance to a sphere of
        // radius 2) lets the beams march into the sphere; the rays must notice and trace from
        // their own starts, ending where unadvanced rays end.
        let big = |q: Vec3| (q - Vec3::new(0.0, 0.0, 5.0)).length() - 2.0;
        let p = params();
        let plain = marches(&p);
        let mut beamed = plain.clone();
        advance_by_beams(&mut beamed, &p, lanes(|q| big(q) + 1.0));
        for (a, b) in plain.iter().zip(&beamed) {
            let (a, b) = (a.unwrap(), b.unwrap());
            assert!(
                big(b.point()) < 0.0,
                "the beam overshot: {}",
                big(b.point())
            );
            let (ra, rb) = (run(a, &p, big), run(b, &p, big));
            assert_eq!(ra.0, Termination::Hit);
            assert_eq!((ra.0, ra.1), (rb.0, rb.1));
            // One evaluation more: the sample that found the start inside.
            assert_eq!(ra.2 + 1, rb.2);
        }
    }

    #[test]
    fn rays_of_different_origins_share_no_beam() {
        let p = params();
        let mut ms = marches(&p);
        let before: Vec<f32> = ms.iter().map(|m| m.unwrap().range().0).collect();
        for (i, m) in ms.iter_mut().enumerate() {
            *m = March::new(&ray(Vec3::new(i as f32 * 0.1, 0.0, 0.0), Vec3::Z), &p, true).ok();
        }
        advance_by_beams(&mut ms, &p, lanes(sphere));
        let after: Vec<f32> = ms.iter().map(|m| m.unwrap().range().0).collect();
        assert_eq!(before.len(), after.len());
        assert!(after.iter().all(|&t| t == 0.0));
    }
}
