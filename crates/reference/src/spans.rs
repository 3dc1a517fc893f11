//! Solids along a ray as sorted lists of spans, and exact CSG on them.
//!
//! A span is the parameter interval `[enter.t, exit.t]` where the ray is inside a solid;
//! each end carries the outward surface normal there (in the frame the span list is
//! expressed in) and the material of the surface. Unbounded ends have `t = ±inf`.

use glam::DVec3;
use marchmesh_scene::MaterialId;

/// One end of a span.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Boundary {
    /// Ray parameter.
    pub t: f64,
    /// Outward normal of the solid at this point (not necessarily unit length).
    pub normal: DVec3,
    /// Surface material.
    pub material: MaterialId,
}

impl Boundary {
    /// A boundary at infinity (`t = ±inf`), never reported as a hit.
    pub fn infinite(t: f64) -> Self {
        Self {
            t,
            normal: DVec3::ZERO,
            material: 0,
        }
    }
}

/// An interval of the ray inside a solid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Where the ray enters.
    pub enter: Boundary,
    /// Where it leaves (`exit.t >= enter.t`).
    pub exit: Boundary,
}

/// The boolean operations on solids.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// Inside either.
    Union,
    /// Inside both.
    Intersection,
    /// Inside the first and not the second.
    Subtraction,
}

/// Combines two sorted, disjoint span lists. Boundaries taken from the subtracted operand
/// have their normals flipped (they bound the difference from the other side).
pub fn combine(a: &[Span], b: &[Span], op: Op) -> Vec<Span> {
    // Events: (t, from_b, is_enter, boundary).
    let mut events: Vec<(f64, bool, bool, Boundary)> = Vec::with_capacity(2 * (a.len() + b.len()));
    for (list, from_b) in [(a, false), (b, true)] {
        for s in list {
            events.push((s.enter.t, from_b, true, s.enter));
            events.push((s.exit.t, from_b, false, s.exit));
        }
    }
    // At equal t, process exits before enters so touching spans do not merge into zero-width
    // artefacts for intersection and enters first for union (keeps touching spans joined).
    events.sort_by(|x, y| {
        x.0.total_cmp(&y.0).then_with(|| match op {
            Op::Union => y.2.cmp(&x.2),
            _ => x.2.cmp(&y.2),
        })
    });
    let inside = |ia: bool, ib: bool| match op {
        Op::Union => ia || ib,
        Op::Intersection => ia && ib,
        Op::Subtraction => ia && !ib,
    };
    let (mut ia, mut ib) = (false, false);
    let mut out = Vec::new();
    let mut open: Option<Boundary> = None;
    for (_, from_b, enter, mut boundary) in events {
        let before = inside(ia, ib);
        if from_b {
            ib = enter;
        } else {
            ia = enter;
        }
        let after = inside(ia, ib);
        if before == after {
            continue;
        }
        if from_b && op == Op::Subtraction {
            boundary.normal = -boundary.normal;
        }
        if after {
            open = Some(boundary);
        } else if let Some(enter) = open.take()
            && (boundary.t > enter.t || enter.t.is_infinite() || boundary.t.is_infinite())
        {
            out.push(Span {
                enter,
                exit: boundary,
            });
        }
    }
    out
}

/// Folds many span lists with `op` (the first list is the minuend for subtraction).
pub fn combine_all(lists: Vec<Vec<Span>>, op: Op) -> Vec<Span> {
    let mut it = lists.into_iter();
    let Some(mut acc) = it.next() else {
        return Vec::new();
    };
    for l in it {
        acc = combine(&acc, &l, op);
    }
    acc
}

/// The first finite boundary in `[t_min, t_max]`: the surface a ray starting at `t_min`
/// meets first (an exit when it starts inside).
pub fn first_boundary(spans: &[Span], t_min: f64, t_max: f64) -> Option<Boundary> {
    spans
        .iter()
        .flat_map(|s| [s.enter, s.exit])
        .filter(|b| b.t.is_finite() && b.t >= t_min && b.t <= t_max)
        .min_by(|x, y| x.t.total_cmp(&y.t))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn span(a: f64, b: f64, m: MaterialId) -> Span {
        Span {
            enter: Boundary {
                t: a,
                normal: DVec3::NEG_X,
                material: m,
            },
            exit: Boundary {
                t: b,
                normal: DVec3::X,
                material: m,
            },
        }
    }

    fn ts(s: &[Span]) -> Vec<(f64, f64)> {
        s.iter().map(|s| (s.enter.t, s.exit.t)).collect()
    }

    #[test]
    fn union_intersection_subtraction() {
        let a = [span(0.0, 2.0, 1), span(5.0, 6.0, 1)];
        let b = [span(1.0, 3.0, 2), span(5.5, 7.0, 2)];
        assert_eq!(
            ts(&combine(&a, &b, Op::Union)),
            vec![(0.0, 3.0), (5.0, 7.0)]
        );
        assert_eq!(
            ts(&combine(&a, &b, Op::Intersection)),
            vec![(1.0, 2.0), (5.5, 6.0)]
        );
        let d = combine(&a, &b, Op::Subtraction);
        assert_eq!(ts(&d), vec![(0.0, 1.0), (5.0, 5.5)]);
        // The carved surface comes from b, facing the other way, with b's material.
        assert_eq!(d[0].exit.material, 2);
        assert_eq!(d[0].exit.normal, DVec3::X);
    }

    #[test]
    fn first_boundary_from_inside_is_the_exit() {
        let s = [span(-1.0, 2.0, 0)];
        assert_eq!(first_boundary(&s, 0.0, 10.0).map(|b| b.t), Some(2.0));
        assert_eq!(first_boundary(&s, -5.0, 10.0).map(|b| b.t), Some(-1.0));
        assert_eq!(first_boundary(&s, 3.0, 10.0), None);
    }
}
