//! The tape specialised per program: 8-lane evaluation of a [`Tape`] without its per-leaf
//! dispatch.
//!
//! [`Tape::eval`] decides at every leaf of every evaluation which shape the leaf is, whether
//! its frame has a linear part, whether it has a bound and where its constants are, and
//! broadcasts every constant into a vector register: on `seed-spheres` (four spheres) that
//! bookkeeping was about a third of the ~300 instructions of an 8-lane evaluation
//! (callgrind, per source line). A [`Kernel`] makes those decisions once, when it is built:
//! consecutive leaves of one kind (shape and frame) become a *run* evaluated by a loop
//! monomorphised for that kind, and every constant is stored already splatted to eight
//! lanes, so it is an operand of the arithmetic instruction instead of a broadcast before it.
//!
//! Every value is bit for bit [`Tape::eval`]'s: the leaves are visited in the tape's order,
//! each leaf's value is the same [`crate::shapes`] function of the same frame arithmetic in
//! the same order, and the running minimum, the scales and the root's bound are the tape's
//! formulas. The unit tests compare them on random programs and points, for every leaf kind.
//!
//! Specialised: spheres, spheres in the parent frame, planes and boxes (the leaves the
//! compiler never bounds, the common ones) in frames with and without a linear part. Every
//! other analytic leaf (and any bounded leaf) is a one-leaf run that calls the tape's own
//! leaf evaluation (`tape::bounded`), so a kernel exists for every tape of analytic leaves.
//! No kernel is built (the tape serves) for tapes with mesh grids and for a root union of two
//! bounded members, which the tape visits nearer first.
//!
//!
//! Measured on `seed-spheres` (callgrind): ~239 instructions per 8-lane evaluation against
//! the tape's ~318, about 1.1x less thread CPU time; the leaves' own arithmetic is about 100.
//! Not yet measured on full renders, so [`crate::Field`]s keep kernels off by default
//! ([`crate::Field::set_kernels`]; the sdf option `kernels`)
//! (`docs/decisions/0023-field-kernels-specialised-per-program.md`).

use crate::lane::{F32x8, Lane, V3};
use crate::leaf::{Leaf, NoGrids};
use crate::program::Affine;
use crate::shapes;
use crate::tape::{Bound, Tape, TapeLeaf, bounded};

/// Eight copies of `s`.
#[inline(always)]
fn s8(s: f32) -> F32x8 {
    F32x8::splat(s)
}

/// Eight copies of each component.
#[inline(always)]
fn v8(v: [f32; 3]) -> [F32x8; 3] {
    v.map(s8)
}

/// A stored splatted 3-vector as lanes.
#[inline(always)]
fn lanes(v: &[F32x8; 3]) -> V3<F32x8> {
    V3::new(v[0], v[1], v[2])
}

/// A leaf frame's map into the leaf's local frame, constants splatted.
trait Frame: Copy + Default {
    /// The frame of `a` when it has this kind.
    fn of(a: &Affine<f32>) -> Option<Self>;
    /// `Affine::apply`, the same operations in the same order.
    fn apply(&self, p: V3<F32x8>) -> V3<F32x8>;
}

/// A translation (`Affine` without a linear part).
#[derive(Debug, Clone, Copy, Default)]
struct Shift([F32x8; 3]);

impl Frame for Shift {
    fn of(a: &Affine<f32>) -> Option<Self> {
        a.lin.is_none().then(|| Shift(v8(a.trans)))
    }
    #[inline(always)]
    fn apply(&self, p: V3<F32x8>) -> V3<F32x8> {
        p + lanes(&self.0)
    }
}

/// A linear map and a translation.
#[derive(Debug, Clone, Copy, Default)]
struct Linear {
    m: [F32x8; 9],
    t: [F32x8; 3],
}

impl Frame for Linear {
    fn of(a: &Affine<f32>) -> Option<Self> {
        a.lin.map(|m| Linear {
            m: m.map(s8),
            t: v8(a.trans),
        })
    }
    #[inline(always)]
    fn apply(&self, p: V3<F32x8>) -> V3<F32x8> {
        let m = &self.m;
        V3::new(
            m[0] * p.x + m[1] * p.y + m[2] * p.z,
            m[3] * p.x + m[4] * p.y + m[5] * p.z,
            m[6] * p.x + m[7] * p.y + m[8] * p.z,
        ) + lanes(&self.t)
    }
}

/// A specialised shape: its constants splatted, its distance the [`Leaf`]'s.
trait Shape: Copy + Default {
    /// The shape of `l` when it has this kind.
    fn of(l: &Leaf<f32>) -> Option<Self>;
    /// `Leaf::distance` of the leaf this was made from.
    fn distance(&self, q: V3<F32x8>) -> F32x8;
}

/// [`Leaf::Sphere`].
#[derive(Debug, Clone, Copy, Default)]
struct Sphere {
    r: F32x8,
}

impl Shape for Sphere {
    fn of(l: &Leaf<f32>) -> Option<Self> {
        match l {
            Leaf::Sphere { r } => Some(Sphere { r: s8(*r) }),
            _ => None,
        }
    }
    #[inline(always)]
    fn distance(&self, q: V3<F32x8>) -> F32x8 {
        shapes::sphere(q, self.r)
    }
}

/// [`Leaf::SphereAt`].
#[derive(Debug, Clone, Copy, Default)]
struct SphereAt {
    c: [F32x8; 3],
    r: F32x8,
    k: F32x8,
}

impl Shape for SphereAt {
    fn of(l: &Leaf<f32>) -> Option<Self> {
        match l {
            Leaf::SphereAt { c, r, k } => Some(SphereAt {
                c: v8(*c),
                r: s8(*r),
                k: s8(*k),
            }),
            _ => None,
        }
    }
    #[inline(always)]
    fn distance(&self, q: V3<F32x8>) -> F32x8 {
        shapes::sphere_at(q, lanes(&self.c), self.r, self.k)
    }
}

/// [`Leaf::Plane`].
#[derive(Debug, Clone, Copy, Default)]
struct Plane {
    n: [F32x8; 3],
    offset: F32x8,
}

impl Shape for Plane {
    fn of(l: &Leaf<f32>) -> Option<Self> {
        match l {
            Leaf::Plane { n, offset } => Some(Plane {
                n: v8(*n),
                offset: s8(*offset),
            }),
            _ => None,
        }
    }
    #[inline(always)]
    fn distance(&self, q: V3<F32x8>) -> F32x8 {
        shapes::plane(q, lanes(&self.n), self.offset)
    }
}

/// [`Leaf::Box`].
#[derive(Debug, Clone, Copy, Default)]
struct Cuboid {
    b: [F32x8; 3],
}

impl Shape for Cuboid {
    fn of(l: &Leaf<f32>) -> Option<Self> {
        match l {
            Leaf::Box { b } => Some(Cuboid { b: v8(*b) }),
            _ => None,
        }
    }
    #[inline(always)]
    fn distance(&self, q: V3<F32x8>) -> F32x8 {
        shapes::box3(q, lanes(&self.b))
    }
}

/// An unbounded leaf of one kind: its value is the tape's `value` (the shape's distance in
/// the leaf's frame times the leaf's distance scale).
#[derive(Debug, Clone, Copy, Default)]
struct Spec<F, S> {
    frame: F,
    shape: S,
    dscale: F32x8,
}

impl<F: Frame, S: Shape> Spec<F, S> {
    fn of(l: &TapeLeaf) -> Option<Self> {
        if l.bound.is_some() {
            return None;
        }
        Some(Spec {
            frame: F::of(&l.to_local)?,
            shape: S::of(&l.shape)?,
            dscale: s8(l.dscale),
        })
    }
    #[inline(always)]
    fn value(&self, p: V3<F32x8>) -> F32x8 {
        self.shape.distance(self.frame.apply(p)) * self.dscale
    }
}

/// Consecutive tape leaves of one kind, each run holding its own leaves (so the loop over
/// runs reads one list per run; with one list per kind in the kernel, the compiler loaded
/// and spilled every list's pointer and length before the loop).
#[derive(Debug, Clone)]
enum Run {
    SphereShift(Vec<Spec<Shift, Sphere>>),
    SphereLinear(Vec<Spec<Linear, Sphere>>),
    SphereAtShift(Vec<Spec<Shift, SphereAt>>),
    SphereAtLinear(Vec<Spec<Linear, SphereAt>>),
    PlaneShift(Vec<Spec<Shift, Plane>>),
    PlaneLinear(Vec<Spec<Linear, Plane>>),
    BoxShift(Vec<Spec<Shift, Cuboid>>),
    BoxLinear(Vec<Spec<Linear, Cuboid>>),
    /// Any other leaf: the tape's leaf evaluation.
    Other(Vec<TapeLeaf>),
}

/// The leaves of a run when it has one kind (`None` for a run of another kind).
type RunList<F, S> = fn(&mut Run) -> Option<&mut Vec<Spec<F, S>>>;

/// Appends `l` to the last run when that run has `l`'s kind of `make`'s, else starts one.
fn extend<F: Frame, S: Shape>(
    runs: &mut Vec<Run>,
    l: &TapeLeaf,
    list: RunList<F, S>,
    make: fn(Vec<Spec<F, S>>) -> Run,
) -> bool {
    let Some(spec) = Spec::<F, S>::of(l) else {
        return false;
    };
    match runs.last_mut().and_then(list) {
        Some(v) => v.push(spec),
        None => runs.push(make(vec![spec])),
    }
    true
}

/// The root union's frame, scale and bound (the frame as the tape applies it).
#[derive(Debug, Clone)]
struct Root {
    to_local: Affine<f32>,
    dscale: F32x8,
    bound: Option<SBound>,
}

/// A node's bound, splatted.
#[derive(Debug, Clone, Copy)]
struct SBound {
    lo: [F32x8; 3],
    hi: [F32x8; 3],
    tau: F32x8,
}

impl SBound {
    fn of(b: &Bound) -> SBound {
        SBound {
            lo: v8(b.lo),
            hi: v8(b.hi),
            tau: s8(b.tau),
        }
    }
}

/// A [`Tape`] specialised for 8-lane distance evaluation, see the [module docs](self).
#[derive(Debug, Clone, Default)]
pub struct Kernel {
    /// `None`: the program is its single leaf.
    root: Option<Root>,
    runs: Vec<Run>,
}

macro_rules! run_list {
    ($v:ident) => {
        |r: &mut Run| match r {
            Run::$v(v) => Some(v),
            _ => None,
        }
    };
}

impl Kernel {
    /// The kernel of `tape`; `None` when the tape has mesh grids or its root is a union of
    /// two bounded members (the tape serves those).
    pub fn of(tape: &Tape) -> Option<Kernel> {
        let mut k = Kernel::default();
        k.rebuild(tape).then_some(k)
    }

    /// [`Kernel::of`] into `self` (reusing its list of runs); false (and `self` unusable)
    /// when the tape has no kernel.
    pub fn rebuild(&mut self, tape: &Tape) -> bool {
        self.runs.clear();
        self.root = None;
        if tape.has_mesh || tape.leaves.is_empty() {
            return false;
        }
        if let Some(r) = &tape.root {
            if r.pair {
                return false;
            }
            self.root = Some(Root {
                to_local: r.to_local.clone(),
                dscale: s8(r.dscale),
                bound: r.bound.as_ref().map(SBound::of),
            });
        }
        let runs = &mut self.runs;
        for l in &tape.leaves {
            let done = extend(runs, l, run_list!(SphereShift), Run::SphereShift)
                || extend(runs, l, run_list!(SphereLinear), Run::SphereLinear)
                || extend(runs, l, run_list!(SphereAtShift), Run::SphereAtShift)
                || extend(runs, l, run_list!(SphereAtLinear), Run::SphereAtLinear)
                || extend(runs, l, run_list!(PlaneShift), Run::PlaneShift)
                || extend(runs, l, run_list!(PlaneLinear), Run::PlaneLinear)
                || extend(runs, l, run_list!(BoxShift), Run::BoxShift)
                || extend(runs, l, run_list!(BoxLinear), Run::BoxLinear);
            if !done {
                match runs.last_mut() {
                    Some(Run::Other(v)) => v.push(l.clone()),
                    _ => runs.push(Run::Other(vec![l.clone()])),
                }
            }
        }
        true
    }

    /// Runs of the kernel (consecutive leaves of one kind).
    pub fn runs(&self) -> usize {
        self.runs.len()
    }

    /// Leaves evaluated through the tape's own leaf evaluation (no specialised kind: every
    /// shape but spheres, planes and boxes, and bounded leaves).
    pub fn fallback_leaves(&self) -> usize {
        self.runs
            .iter()
            .map(|r| match r {
                Run::Other(v) => v.len(),
                _ => 0,
            })
            .sum()
    }

    /// The distances at eight points, bit for bit [`Tape::eval`]'s (`Tape::eval::<F32x8,
    /// false>`) on the tape the kernel was built from.
    #[cfg_attr(not(debug_assertions), inline)]
    pub fn eval(&self, p: V3<F32x8>) -> F32x8 {
        let Some(root) = &self.root else {
            return self.union(p);
        };
        match &root.bound {
            None => self.root_union(root, p),
            Some(b) => {
                let zero = F32x8::c(0.0);
                let l = shapes::box_distance(p, lanes(&b.lo), lanes(&b.hi));
                let outside = F32x8::lt(zero, l);
                let skip = F32x8::and(outside, F32x8::le(b.tau, l));
                if F32x8::all(skip) {
                    return l;
                }
                let c = self.root_union(root, p);
                let cc = c.min(b.tau);
                let g = F32x8::select(outside, l.max(cc), cc);
                F32x8::select(skip, l, g)
            }
        }
    }

    /// The root union's value without its bound, `p` in the root's parent frame.
    #[inline(always)]
    fn root_union(&self, root: &Root, p: V3<F32x8>) -> F32x8 {
        self.union(root.to_local.apply(p)) * root.dscale
    }

    /// The running minimum over the leaves in the tape's order (a single leaf's value when
    /// the program is one leaf).
    #[inline(always)]
    fn union(&self, q: V3<F32x8>) -> F32x8 {
        let mut best: Option<F32x8> = None;
        for r in &self.runs {
            best = Some(match r {
                Run::SphereShift(v) => fold(v, q, best),
                Run::SphereLinear(v) => fold(v, q, best),
                Run::SphereAtShift(v) => fold(v, q, best),
                Run::SphereAtLinear(v) => fold(v, q, best),
                Run::PlaneShift(v) => fold(v, q, best),
                Run::PlaneLinear(v) => fold(v, q, best),
                Run::BoxShift(v) => fold(v, q, best),
                Run::BoxLinear(v) => fold(v, q, best),
                Run::Other(v) => {
                    let mut b = best;
                    for l in v {
                        let (d, _) = bounded::<F32x8, false, NoGrids>(l, q, b, NoGrids);
                        b = Some(match b {
                            Some(b) => b.min(d),
                            None => d,
                        });
                    }
                    b.expect("a run holds at least one leaf")
                }
            });
        }
        best.expect("a kernel holds at least one leaf")
    }
}

/// The running minimum `best` (none before the first leaf) folded over a run of one kind.
#[inline(always)]
fn fold<F: Frame, S: Shape>(run: &[Spec<F, S>], q: V3<F32x8>, best: Option<F32x8>) -> F32x8 {
    let (mut b, rest) = match best {
        Some(b) => (b, run),
        None => (run[0].value(q), &run[1..]),
    };
    for l in rest {
        b = b.min(l.value(q));
    }
    b
}
