//! The field's leaves: every primitive a program evaluates (analytic shapes and mesh grids),
//! and the one entry that computes a leaf's distance, `Leaf::distance`, which the
//! interpreter ([`crate::program::Program::eval`]) and the tape ([`crate::tape::Tape`]) both
//! call, so their values agree bit for bit by construction. The formulas themselves live in
//! [`crate::shapes`].
//!
//! A new shape: a variant here, its arm in `Leaf::distance` and [`Leaf::cast`] (the
//! compiler flags both), and its arm in [`crate::compile`]. Optional: a directional
//! Lipschitz bound (`program::segment::leaf_lambda`) and a receding test
//! (`Leaf::outward`) for convex shapes.

use crate::lane::{Lane, Scalar, V3};
use crate::program::GridSampler;
use crate::shapes::{self, TriData};

/// A primitive in its local frame, parameters in scalar type `S`.
#[derive(Debug, Clone, PartialEq)]
pub enum Leaf<S> {
    /// [`shapes::sphere`].
    Sphere {
        /// Radius.
        r: S,
    },
    /// A sphere in the parent frame (centre `c`, radius `r`, `k = |c|^2 - r^2`), evaluated
    /// as `(|p|^2 - 2 p.c + k) / (|p - c| + r)`: the same value as `|p - c| - r`, but
    /// without the cancellation of `|p - c| ~ r` in f32 when a huge sphere (a ground) passes
    /// near the camera: the terms stay small in render space.
    SphereAt {
        /// Centre.
        c: [S; 3],
        /// Radius.
        r: S,
        /// `|c|^2 - r^2`.
        k: S,
    },
    /// [`shapes::plane`].
    Plane {
        /// Unit normal.
        n: [S; 3],
        /// Offset.
        offset: S,
    },
    /// [`shapes::box3`].
    Box {
        /// Half extents.
        b: [S; 3],
    },
    /// [`shapes::ellipsoid`].
    Ellipsoid {
        /// 1 / radii.
        inv_r: [S; 3],
        /// Smallest radius.
        rmin: S,
    },
    /// [`shapes::cylinder`].
    Cylinder {
        /// Radius.
        r: S,
        /// Half height.
        h: S,
    },
    /// [`shapes::torus`].
    Torus {
        /// Major radius.
        big: S,
        /// Minor radius.
        small: S,
    },
    /// [`shapes::rounded_box`].
    RoundedBox {
        /// Half extents of the inner (unrounded) box.
        b: [S; 3],
        /// Rounding radius.
        r: S,
    },
    /// [`shapes::capsule`].
    Capsule {
        /// Half the segment's length.
        h: S,
        /// Radius.
        r: S,
    },
    /// [`shapes::capped_cone`].
    CappedCone {
        /// Half height.
        h: S,
        /// Radius at `y = -h`.
        r1: S,
        /// Radius at `y = h`.
        r2: S,
        /// `1 / ((r2 - r1)^2 + 4 h^2)`.
        inv_k2: S,
    },
    /// [`shapes::triangle`].
    Triangle(Box<TriData<S>>),
    /// A baked mesh grid (index into the field's grid list).
    Mesh {
        /// Grid index.
        grid: u32,
    },
}

impl<S: Scalar> Leaf<S> {
    /// The leaf's signed distance (a 1-Lipschitz bound for [`Leaf::Ellipsoid`], unsigned for
    /// [`Leaf::Triangle`], the grid's value for [`Leaf::Mesh`]) at `q` in its local frame,
    /// before the node's distance scale. Mesh grids are sampled from `grids` (NaN from
    /// [`NoGrids`]; an index past a [`GridList`] panics, a compiler bug).
    ///
    /// Inlined at every call in optimized builds; one out-of-line copy per instantiation in
    /// builds with debug assertions, where the evaluators' dozens of inlined copies of this
    /// match made one function of ~700k lines of LLVM IR and minutes of compile time
    /// (`docs/decisions/0016-evaluators-compiled-once-in-test-builds.md`).
    #[cfg_attr(debug_assertions, inline(never))]
    #[cfg_attr(not(debug_assertions), inline(always))]
    pub(crate) fn distance<T: Lane<S = S>, G: GridSource>(&self, q: V3<T>, grids: G) -> T {
        match self {
            Leaf::Sphere { r } => shapes::sphere(q, T::splat(*r)),
            Leaf::SphereAt { c, r, k } => {
                shapes::sphere_at(q, V3::splat3(*c), T::splat(*r), T::splat(*k))
            }
            Leaf::Plane { n, offset } => shapes::plane(q, V3::splat3(*n), T::splat(*offset)),
            Leaf::Box { b } => shapes::box3(q, V3::splat3(*b)),
            Leaf::Ellipsoid { inv_r, rmin } => {
                shapes::ellipsoid(q, V3::splat3(*inv_r), T::splat(*rmin))
            }
            Leaf::Cylinder { r, h } => shapes::cylinder(q, T::splat(*r), T::splat(*h)),
            Leaf::Torus { big, small } => shapes::torus(q, T::splat(*big), T::splat(*small)),
            Leaf::RoundedBox { b, r } => shapes::rounded_box(q, V3::splat3(*b), T::splat(*r)),
            Leaf::Capsule { h, r } => shapes::capsule(q, T::splat(*h), T::splat(*r)),
            Leaf::CappedCone { h, r1, r2, inv_k2 } => shapes::capped_cone(
                q,
                T::splat(*h),
                T::splat(*r1),
                T::splat(*r2),
                T::splat(*inv_k2),
            ),
            Leaf::Triangle(t) => shapes::triangle(q, t),
            Leaf::Mesh { grid } => grids.sample(*grid, q),
        }
    }

    /// The same leaf with its constants converted to scalar type `U`.
    pub fn cast<U: Scalar>(&self) -> Leaf<U> {
        let c = |v: S| U::from_f64(v.to_f64());
        let c3 = |v: [S; 3]| v.map(c);
        match self {
            Leaf::Sphere { r } => Leaf::Sphere { r: c(*r) },
            Leaf::SphereAt { c: cen, r, k } => Leaf::SphereAt {
                c: c3(*cen),
                r: c(*r),
                k: c(*k),
            },
            Leaf::Plane { n, offset } => Leaf::Plane {
                n: c3(*n),
                offset: c(*offset),
            },
            Leaf::Box { b } => Leaf::Box { b: c3(*b) },
            Leaf::Ellipsoid { inv_r, rmin } => Leaf::Ellipsoid {
                inv_r: c3(*inv_r),
                rmin: c(*rmin),
            },
            Leaf::Cylinder { r, h } => Leaf::Cylinder { r: c(*r), h: c(*h) },
            Leaf::Torus { big, small } => Leaf::Torus {
                big: c(*big),
                small: c(*small),
            },
            Leaf::RoundedBox { b, r } => Leaf::RoundedBox {
                b: c3(*b),
                r: c(*r),
            },
            Leaf::Capsule { h, r } => Leaf::Capsule { h: c(*h), r: c(*r) },
            Leaf::CappedCone { h, r1, r2, inv_k2 } => Leaf::CappedCone {
                h: c(*h),
                r1: c(*r1),
                r2: c(*r2),
                inv_k2: c(*inv_k2),
            },
            Leaf::Triangle(t) => Leaf::Triangle(Box::new(TriData {
                a: c3(t.a),
                b: c3(t.b),
                c: c3(t.c),
                ba: c3(t.ba),
                cb: c3(t.cb),
                ac: c3(t.ac),
                en: t.en.map(c3),
                n: c3(t.n),
                inv2: c3(t.inv2),
            })),
            Leaf::Mesh { grid } => Leaf::Mesh { grid: *grid },
        }
    }
}

impl Leaf<f32> {
    /// For a convex leaf, the direction its value grows fastest at `lq` (local frame; not
    /// unit length), where that is the outward one; `None` for leaves that are not convex
    /// and for points on or inside where it is not. What [`crate::tape::Tape::recedes`] uses
    /// to leave a leaf behind; a shape without an answer is only never left behind early.
    pub(crate) fn outward(&self, lq: V3<f32>) -> Option<V3<f32>> {
        match self {
            Leaf::Sphere { .. } => Some(lq),
            Leaf::SphereAt { c, .. } => Some(lq - V3::splat3(*c)),
            Leaf::Plane { n, .. } => Some(V3::splat3(*n)),
            Leaf::Box { b } => {
                let e = V3::new(
                    lq.x - lq.x.clamp(-b[0], b[0]),
                    lq.y - lq.y.clamp(-b[1], b[1]),
                    lq.z - lq.z.clamp(-b[2], b[2]),
                );
                (e.len2() > 0.0).then_some(e)
            }
            Leaf::Ellipsoid { inv_r, .. } => {
                let w = V3::splat3(*inv_r);
                Some(lq.mul_elem(w).mul_elem(w))
            }
            Leaf::Cylinder { r, h } => {
                let rad = (lq.x * lq.x + lq.z * lq.z).sqrt();
                let k = if rad > *r { 1.0 - *r / rad } else { 0.0 };
                let e = V3::new(lq.x * k, lq.y - lq.y.clamp(-*h, *h), lq.z * k);
                (e.len2() > 0.0).then_some(e)
            }
            // Outside the rounding only: inside it the value still grows along `e`, but the
            // point is in the solid.
            Leaf::RoundedBox { b, r } => {
                let e = V3::new(
                    lq.x - lq.x.clamp(-b[0], b[0]),
                    lq.y - lq.y.clamp(-b[1], b[1]),
                    lq.z - lq.z.clamp(-b[2], b[2]),
                );
                (e.len2() > r * r).then_some(e)
            }
            Leaf::Capsule { h, r } => {
                let e = V3::new(lq.x, lq.y - lq.y.clamp(-*h, *h), lq.z);
                (e.len2() > r * r).then_some(e)
            }
            _ => None,
        }
    }
}

/// Where a leaf's mesh grids are sampled. A tape without mesh leaves is evaluated with
/// [`NoGrids`], so its leaf loop holds no call: a possible call there (even out of line)
/// made the analytic leaves' values spill around it, 8% more instructions per image on
/// seed-spheres.
pub(crate) trait GridSource: Copy {
    /// Mesh grid `grid`'s value at `q` (its local frame), before the leaf's `dscale`.
    fn sample<T: Lane>(self, grid: u32, q: V3<T>) -> T;
}

/// No grids: a tape without mesh leaves (NaN if one were met).
#[derive(Clone, Copy)]
pub(crate) struct NoGrids;

impl GridSource for NoGrids {
    #[inline(always)]
    fn sample<T: Lane>(self, _grid: u32, _q: V3<T>) -> T {
        T::c(f64::NAN)
    }
}

/// The field's grids; panics on an index past them.
#[derive(Clone, Copy)]
pub(crate) struct GridList<'a>(pub(crate) &'a [Box<dyn GridSampler>]);

impl GridSource for GridList<'_> {
    #[inline(always)]
    fn sample<T: Lane>(self, grid: u32, q: V3<T>) -> T {
        T::sample_grid(self.0[grid as usize].as_ref(), q.x, q.y, q.z)
    }
}
