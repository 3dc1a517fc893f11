//! Restricting a field to what a bundle of rays can reach.
//!
//! A ray only ever meets surfaces inside the region it sweeps, so a tracer may march it
//! through the field of just the objects whose bounding boxes that region touches: the
//! minimum over fewer objects is larger, so the steps are longer, and it is still a safe
//! bound along the ray because a dropped object cannot lie on it. This is how fidget prunes
//! its evaluation tapes per image region (Keeter 2020, "Massively Parallel Rendering of
//! Complex Closed-Form Implicit Surfaces"), done here with boxes instead of intervals, per
//! bundle of rays from one origin (a cone), on the union hierarchy the compiler builds:
//! the cost of a step then depends on the objects near the bundle, not on the scene's object
//! count.
//!
//! Only unions reached from the root through identity frames are pruned (the compiler's
//! synthetic groups and the scene's top-level list), because their children's boxes are in
//! render space; every other node is kept or dropped whole.

use std::sync::Arc;

use glam::{DVec3, Vec3};

use marchmesh_scene::MaterialId;

use crate::Field;
use crate::jit::Jit;
use crate::kernel::Kernel;
use crate::lane::{F32x8, V3};
use crate::program::{Instr, Op, Program};
use crate::tape::{Tape, tape_leaf};

/// Rays from `origin` whose directions lie in a pyramid around `axis`: in the frame
/// (`u`, `v`, `axis`), a direction `d` is inside when `u.d / axis.d` lies in `[u_lo, u_hi]`
/// and `v.d / axis.d` in `[v_lo, v_hi]`, each ray at most `t_max` long. The region a bundle
/// of rays sweeps: a run of one image row makes a thin wedge, a tile a square pyramid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayCone {
    /// Common origin of the rays (render space).
    pub origin: DVec3,
    /// Unit axis (the mean direction).
    pub axis: DVec3,
    /// Unit vector perpendicular to `axis`.
    pub u: DVec3,
    /// `axis x u`.
    pub v: DVec3,
    /// Slope bounds along `u`: `[lo, hi]` of `u.d / axis.d`.
    pub u_slope: [f64; 2],
    /// Slope bounds along `v`.
    pub v_slope: [f64; 2],
    /// Longest ray (world units; may be infinite).
    pub t_max: f64,
    /// Widening of every box's bounding sphere, absolute part (world units): a tracer that
    /// decides hits within a shell of some width around surfaces must keep objects whose
    /// shell the rays may touch.
    pub margin_abs: f64,
    /// Widening per unit distance from the origin (the relative part of the shell).
    pub margin_rel: f64,
}

impl RayCone {
    /// Steepest slope (tangent of the angle from the axis) this module prunes for: wider
    /// bundles reach nearly every box anyway.
    pub const MAX_SLOPE: f64 = 2.0;

    /// The pyramid around rays `(origin, dirs[i])` of length at most `t_max`; `None` when
    /// there are no directions, a direction is not finite, or they spread wider than
    /// [`RayCone::MAX_SLOPE`] from their mean (nothing worth pruning). Directions need not be
    /// unit length.
    pub fn around(
        origin: Vec3,
        dirs: impl Iterator<Item = Vec3> + Clone,
        t_max: f64,
        margin_abs: f64,
        margin_rel: f64,
    ) -> Option<RayCone> {
        let unit = |d: Vec3| d.as_dvec3().try_normalize();
        let mut sum = DVec3::ZERO;
        for d in dirs.clone() {
            sum += unit(d)?;
        }
        let axis = sum.try_normalize()?;
        // Align `u` with the spread from the first to the last direction (along a run of an
        // image row), so a row makes a thin wedge rather than a square in a rotated frame.
        let (first, last) = (dirs.clone().next()?, dirs.clone().last()?);
        let spread = unit(last)? - unit(first)?;
        let u = (spread - axis * spread.dot(axis))
            .try_normalize()
            .unwrap_or_else(|| axis.any_orthonormal_vector());
        let v = axis.cross(u);
        let (mut u_slope, mut v_slope) = (
            [f64::INFINITY, f64::NEG_INFINITY],
            [f64::INFINITY, f64::NEG_INFINITY],
        );
        for d in dirs {
            let d = unit(d)?;
            let a = d.dot(axis);
            if a <= 0.0 {
                return None;
            }
            let (su, sv) = (d.dot(u) / a, d.dot(v) / a);
            u_slope = [u_slope[0].min(su), u_slope[1].max(su)];
            v_slope = [v_slope[0].min(sv), v_slope[1].max(sv)];
        }
        // A little wider than the outermost rays, for rounding of f32 directions.
        let pad = 1e-6;
        let (u_slope, v_slope) = (
            [u_slope[0] - pad, u_slope[1] + pad],
            [v_slope[0] - pad, v_slope[1] + pad],
        );
        let steep = [u_slope[0], u_slope[1], v_slope[0], v_slope[1]]
            .iter()
            .any(|s| s.abs() > Self::MAX_SLOPE);
        (!steep).then_some(RayCone {
            origin: origin.as_dvec3(),
            axis,
            u,
            v,
            u_slope,
            v_slope,
            t_max,
            margin_abs,
            margin_rel,
        })
    }

    /// Whether a ray of the bundle may come within the margin of the box `[lo, hi]`
    /// (conservative: tests the box grown by the margin against the pyramid's four side
    /// planes and the plane through the origin, and the box's bounding sphere against the
    /// rays' length; a box with a non-finite corner is always reached).
    pub fn may_reach(&self, lo: [f32; 3], hi: [f32; 3]) -> bool {
        Wedge::of(self).may_reach(lo, hi)
    }
}

/// A [`RayCone`] with its side planes' unit outward normals computed once, for the many
/// box tests of one restriction.
struct Wedge {
    origin: DVec3,
    axis: DVec3,
    /// Outward unit normals of the four side planes (through the origin).
    sides: [DVec3; 4],
    t_max: f64,
    margin_abs: f64,
    margin_rel: f64,
}

impl Wedge {
    fn of(cone: &RayCone) -> Wedge {
        // The plane of slope `s` along `w` holds the directions `axis + s w`; its normal
        // `w - s axis` (outward `sign` times), normalised.
        let side =
            |w: DVec3, s: f64, sign: f64| (w - cone.axis * s) * (sign / (1.0 + s * s).sqrt());
        Wedge {
            origin: cone.origin,
            axis: cone.axis,
            sides: [
                side(cone.u, cone.u_slope[1], 1.0),
                side(cone.u, cone.u_slope[0], -1.0),
                side(cone.v, cone.v_slope[1], 1.0),
                side(cone.v, cone.v_slope[0], -1.0),
            ],
            t_max: cone.t_max,
            margin_abs: cone.margin_abs,
            margin_rel: cone.margin_rel,
        }
    }

    /// [`RayCone::may_reach`].
    #[inline]
    fn may_reach(&self, lo: [f32; 3], hi: [f32; 3]) -> bool {
        let lo = DVec3::from(lo.map(f64::from));
        let hi = DVec3::from(hi.map(f64::from));
        if !(lo.is_finite() && hi.is_finite()) {
            return true;
        }
        let c = (lo + hi) * 0.5 - self.origin;
        let half = (hi - lo) * 0.5;
        let half_diag = half.length();
        let dist = c.length();
        let margin = self.margin_abs + self.margin_rel * (dist + half_diag);
        let radius = half_diag + margin;
        if dist <= radius {
            return true;
        }
        // The box grown by the margin lies beyond a plane through the origin with unit
        // normal `n` when its centre is farther than its support `|n| . half + margin`.
        let beyond = |n: DVec3| n.dot(c) > n.abs().dot(half) + margin;
        if dist - radius > self.t_max || beyond(-self.axis) {
            return false;
        }
        !self.sides.iter().any(|&n| beyond(n))
    }
}

/// A field restricted to a [`RayCone`] by [`Field::restrict_to`]: the same values as the
/// field wherever no dropped object is nearer (always on the bundle's rays, within the
/// cone's margin), larger elsewhere. Only for tracing rays of that bundle.
#[derive(Debug, Clone, Default)]
pub struct Restricted {
    prog: Program<f32>,
    dropped: usize,
    /// `prog` as a tape, when it is a small union of tape leaves (`taped`).
    tape: Tape,
    taped: bool,
    /// `tape` specialised ([`crate::kernel`]), when it has a kernel and the field's kernels
    /// are on (`kerneled`).
    kernel: Kernel,
    kerneled: bool,
    /// The program compiled ([`crate::jit`]), when the field's JIT compilation is on and it
    /// compiles (shared through the field's cache, keyed by `kept`).
    jit: Option<Arc<Jit>>,
    /// The field's nodes the restriction kept, in the order copied (what determines the
    /// restricted program); listed only when the field's JIT compilation is on, else empty.
    kept: Vec<u32>,
    /// Buffer of [`flatten`].
    scratch: Vec<Instr<f32>>,
}

impl Restricted {
    /// Nodes of the restricted program.
    pub fn node_count(&self) -> usize {
        self.prog.instrs.len()
    }

    /// Whether the 8-lane evaluations (and gradients) under this restriction run a flat
    /// [`Tape`]: the restricted program is one tape leaf or a union of at most
    /// [`Tape::MAX_LEAVES`] of them (nested unions of the compiler's hierarchy are
    /// flattened). Otherwise they run the interpreter.
    pub fn is_taped(&self) -> bool {
        self.taped
    }

    /// Whether the 8-lane distances under this restriction run a specialised
    /// [`crate::kernel::Kernel`] (its tape has one and the field's kernels are on).
    pub fn is_kerneled(&self) -> bool {
        self.kerneled
    }

    /// Whether the 8-lane distances under this restriction run a compiled
    /// [`crate::jit::Jit`] (its tape compiles and the field's JIT compilation is on).
    pub fn is_jitted(&self) -> bool {
        self.jit.is_some()
    }

    /// Nodes the restriction dropped.
    pub fn dropped(&self) -> usize {
        self.dropped
    }
}

impl Field {
    /// Restricts the f32 program to the objects `cone` may reach, into `out` (its buffer is
    /// reused). Evaluate it with [`Field::restricted_distance_x8`] on this same field. The
    /// kept part of the compiler's union hierarchy is flattened into one union when it has
    /// at most [`Tape::MAX_LEAVES`] tape leaves, so the bundle runs a [`Tape`].
    pub fn restrict_to(&self, cone: &RayCone, out: &mut Restricted) {
        out.prog.instrs.clear();
        out.kept.clear();
        if !self.p32.instrs.is_empty() {
            // The kept nodes key the JIT cache: listed only when it is read.
            let emit = if self.jits {
                emit::<true>
            } else {
                emit::<false>
            };
            emit(
                &self.p32.instrs,
                0,
                &Wedge::of(cone),
                &mut out.prog.instrs,
                &mut out.kept,
            );
        }
        out.dropped = self.p32.instrs.len() - out.prog.instrs.len().min(self.p32.instrs.len());
        flatten(&mut out.prog.instrs, &mut out.scratch);
        out.taped = out.tape.rebuild(&out.prog);
        out.jit = if self.jits && out.taped {
            self.jit_cache.get_or_compile(&out.kept, &out.tape)
        } else {
            None
        };
        out.kerneled =
            out.jit.is_none() && self.kernels && out.taped && out.kernel.rebuild(&out.tape);
    }

    /// Distances at eight points under a restriction made by [`Field::restrict_to`] on this
    /// field (same interpreter as [`Field::distance_x8`]; an empty restriction is 1e30).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_distance_x8(&self, r: &Restricted, p: [Vec3; 8]) -> [f32; 8] {
        self.restricted_distance_lanes(r, V3::from_points(p)).0
    }

    /// Distances of eight points given as SoA lanes under a restriction (per lane the same
    /// as [`Field::restricted_distance`]).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_distance_lanes(&self, r: &Restricted, p: V3<F32x8>) -> F32x8 {
        if let Some(j) = &r.jit {
            j.eval(p)
        } else if r.kerneled {
            r.kernel.eval(p)
        } else if r.taped {
            r.tape.eval::<F32x8, false>(p, &self.grids).0
        } else {
            self.eval::<F32x8, false>(&r.prog, p).0
        }
    }

    /// Distances and materials at eight points under a restriction (per lane the same as
    /// [`Field::restricted_distance_x8`]; materials as [`Field::distance_material_x8`]
    /// reports them).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_distance_material_x8(
        &self,
        r: &Restricted,
        p: [Vec3; 8],
    ) -> ([f32; 8], [MaterialId; 8]) {
        let p = V3::from_points(p);
        let (d, m) = if r.taped {
            r.tape.eval::<F32x8, true>(p, &self.grids)
        } else {
            self.eval::<F32x8, true>(&r.prog, p)
        };
        (d.0, m)
    }

    /// Normals' gradients at eight points on surfaces under a restriction: per lane the
    /// analytic gradient of the kept leaf nearest to the point ([`Tape::nearest_gradients`]),
    /// which at a hit of the bundle is the gradient of the surface hit (its object is kept).
    /// Lanes nearest a mesh grid get NaN. `None` when the restriction has no tape (it has
    /// CSG, repetition or too many leaves) or no lane has a gradient.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_nearest_gradients_x8(
        &self,
        r: &Restricted,
        p: [Vec3; 8],
    ) -> Option<[Vec3; 8]> {
        if !r.taped {
            return None;
        }
        let g = r.tape.nearest_gradients(V3::from_points(p), &self.grids);
        g.iter().any(|v| v.is_finite()).then_some(g)
    }

    /// [`Field::segment_step`] under a restriction made by [`Field::restrict_to`] on this
    /// field (only for rays of the restricted bundle).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_segment_step(
        &self,
        r: &Restricted,
        p: Vec3,
        dir: Vec3,
        len: f32,
    ) -> (f32, f32) {
        self.segment_in(&r.prog, p, dir, len)
    }

    /// [`Field::restricted_segment_step`] on eight lanes (as [`Field::segment_lanes`]);
    /// `None` when the restriction has no tape.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_segment_lanes(
        &self,
        r: &Restricted,
        p: V3<F32x8>,
        d: V3<F32x8>,
        len: F32x8,
    ) -> Option<(F32x8, F32x8)> {
        r.taped.then(|| r.tape.segment(p, d, len, &self.grids))
    }

    /// [`Field::recedes`] under a restriction made by [`Field::restrict_to`] on this field
    /// (only for rays of the restricted bundle); false when the restriction has no tape.
    pub fn restricted_recedes(&self, r: &Restricted, p: Vec3, dir: Vec3) -> bool {
        r.taped && r.tape.recedes(p, dir)
    }

    /// The scalar distance under a restriction (same values per point as
    /// [`Field::restricted_distance_x8`]).
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn restricted_distance(&self, r: &Restricted, p: Vec3) -> f32 {
        self.eval::<f32, false>(&r.prog, V3::new(p.x, p.y, p.z)).0
    }
}

/// Whether node `ins` reads points in its parent's frame unchanged.
fn identity_frame(ins: &Instr<f32>) -> bool {
    ins.to_local.lin.is_none() && ins.to_local.trans == [0.0; 3] && ins.dscale == 1.0
}

/// Emits node `i` of `src` restricted to `cone` into `out` (with `KEEP`, each emitted
/// node's index in `src` into `kept`, in step with `out`); false when nothing of it can be
/// reached (then nothing is emitted).
fn emit<const KEEP: bool>(
    src: &[Instr<f32>],
    i: usize,
    cone: &Wedge,
    out: &mut Vec<Instr<f32>>,
    kept: &mut Vec<u32>,
) -> bool {
    let ins = &src[i];
    // Every node carries its box (in its parent's frame), also where `has_bound` is off
    // because testing it would cost more than the cheap leaf it guards.
    if !cone.may_reach(ins.lo, ins.hi) {
        return false;
    }
    let end = ins.end as usize;
    if matches!(ins.op, Op::Union) && identity_frame(ins) {
        let at = out.len();
        out.push(ins.clone());
        if KEEP {
            kept.push(i as u32);
        }
        let mut j = i + 1;
        let mut children = 0;
        while j < end {
            children += usize::from(emit::<KEEP>(src, j, cone, out, kept));
            j = src[j].end as usize;
        }
        match children {
            0 => {
                out.truncate(at);
                if KEEP {
                    kept.truncate(at);
                }
                return false;
            }
            1 => {
                // A union of one child is that child (same frame): drop the wrapper, a box
                // test and a dispatch per evaluation.
                out.remove(at);
                if KEEP {
                    kept.remove(at);
                }
                for n in &mut out[at..] {
                    n.end -= 1;
                }
            }
            _ => out[at].end = out.len() as u32,
        }
        return true;
    }
    // Kept whole: copy the subtree with its end indices moved to the new position.
    let shift = out.len() as i64 - i as i64;
    if KEEP {
        kept.extend(i as u32..end as u32);
    }
    out.extend(src[i..end].iter().map(|n| {
        let mut n = n.clone();
        n.end = (i64::from(n.end) + shift) as u32;
        n
    }));
    true
}

/// Rewrites a restricted program that is a union of identity-frame unions of tape
/// leaves (what [`emit`] leaves of the compiler's union hierarchy) as one union of those
/// leaves, in the same order, when there are at most [`Tape::MAX_LEAVES`] of them, so the
/// bundle gets a [`Tape`]. A union of unions is the union of their leaves: the value is the
/// exact minimum over the kept leaves either way; the nested groups only added box tests
/// (their `tau` is infinite) and a recursion per level. Other programs are left as they are.
fn flatten(instrs: &mut Vec<Instr<f32>>, scratch: &mut Vec<Instr<f32>>) {
    let Some(root) = instrs.first() else {
        return;
    };
    if !matches!(root.op, Op::Union) || root.end as usize != instrs.len() {
        return;
    }
    let mut leaves = 0;
    let mut nested = false;
    for (k, ins) in instrs.iter().enumerate().skip(1) {
        if matches!(ins.op, Op::Union) {
            if !identity_frame(ins) {
                return;
            }
            nested = true;
        } else if tape_leaf(&ins.op) && ins.end as usize == k + 1 {
            leaves += 1;
        } else {
            return;
        }
    }
    if !nested || leaves > Tape::MAX_LEAVES {
        return;
    }
    scratch.clear();
    scratch.extend(instrs.drain(1..).filter(|i| !matches!(i.op, Op::Union)));
    instrs[0].end = (leaves + 1) as u32;
    for (k, mut leaf) in scratch.drain(..).enumerate() {
        leaf.end = (k + 2) as u32;
        instrs.push(leaf);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cone(half: f32) -> RayCone {
        let dirs = [
            Vec3::new(-half, -half, 1.0),
            Vec3::new(half, -half, 1.0),
            Vec3::new(-half, half, 1.0),
            Vec3::new(half, half, 1.0),
        ];
        RayCone::around(Vec3::ZERO, dirs.into_iter(), f64::INFINITY, 0.0, 0.0).unwrap()
    }

    #[test]
    fn boxes_in_front_are_reached_boxes_beside_are_not() {
        let c = cone(0.01);
        assert!(c.may_reach([-0.1, -0.1, 5.0], [0.1, 0.1, 5.2]));
        assert!(!c.may_reach([2.0, 2.0, 5.0], [2.2, 2.2, 5.2]));
        // Behind the origin.
        assert!(!c.may_reach([-0.1, -0.1, -5.2], [0.1, 0.1, -5.0]));
        // Containing the origin.
        assert!(c.may_reach([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]));
        // Unbounded.
        assert!(c.may_reach([f32::NEG_INFINITY, -1.0, 0.0], [f32::INFINITY, -0.9, 1.0]));
        // Beyond the rays' length.
        let short = RayCone { t_max: 3.0, ..c };
        assert!(!short.may_reach([-0.1, -0.1, 5.0], [0.1, 0.1, 5.2]));
    }

    #[test]
    fn a_row_makes_a_thin_wedge() {
        // 64 rays along x, one pixel row: boxes above or below the row are not reached.
        let dirs = (0..64).map(|i| Vec3::new((i as f32 - 31.5) * 0.002, 0.0, 1.0));
        let c = RayCone::around(Vec3::ZERO, dirs, 100.0, 0.0, 0.0).unwrap();
        assert!(c.may_reach([0.4, -0.01, 9.9], [0.42, 0.01, 10.1]));
        assert!(!c.may_reach([0.0, 0.1, 9.9], [0.02, 0.12, 10.1]));
        assert!(!c.may_reach([0.0, -0.12, 9.9], [0.02, -0.1, 10.1]));
        assert!(!c.may_reach([1.0, -0.01, 9.9], [1.02, 0.01, 10.1]));
    }

    #[test]
    fn the_margin_keeps_boxes_the_shell_may_touch() {
        // A box just beside the pyramid at distance ~5: the margin reaches it.
        let c = cone(0.01);
        let (lo, hi) = ([0.25, -0.05, 4.95], [0.35, 0.05, 5.05]);
        assert!(!c.may_reach(lo, hi));
        let wide = RayCone {
            margin_rel: 0.02,
            ..c
        };
        assert!(wide.may_reach(lo, hi));
    }

    #[test]
    fn the_pyramid_covers_its_directions() {
        let dirs = [
            Vec3::new(0.1, 0.0, 1.0),
            Vec3::new(-0.1, 0.05, 1.0),
            Vec3::new(0.0, -0.1, 1.0),
        ];
        let c = RayCone::around(Vec3::ZERO, dirs.iter().copied(), 10.0, 0.0, 0.0).unwrap();
        for d in dirs {
            // A tiny box on each ray is reached.
            let p = (d.normalize() * 5.0).to_array();
            let lo = p.map(|x| x - 1e-4);
            let hi = p.map(|x| x + 1e-4);
            assert!(c.may_reach(lo, hi), "{d:?}");
        }
        let none = |dirs: &[Vec3]| RayCone::around(Vec3::ZERO, dirs.iter().copied(), 1.0, 0.0, 0.0);
        assert!(none(&[Vec3::Z, -Vec3::Z]).is_none());
        assert!(none(&[]).is_none());
        assert!(none(&[Vec3::new(f32::NAN, 0.0, 1.0)]).is_none());
        // 70 degrees either side of the mean: slope 2.7.
        let (sn, cs) = 70f32.to_radians().sin_cos();
        assert!(none(&[Vec3::new(sn, 0.0, cs), Vec3::new(-sn, 0.0, cs)]).is_none());
    }
}
