//! The blend (`SmoothOp::Blend`, `program::blend`): its value against an independent solve
//! (children sorted, the active set found by scanning), the same value in any child order,
//! its deficit bound, 1-Lipschitz and non-decreasing, eight lanes against one,
//! and a blend with more children near a point than the solve buffers.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldOptions};
use marchmesh_scene::bounds::blend_deficit;
use marchmesh_scene::{Node, NodeKind, Shape, SmoothOp};

fn node(kind: NodeKind, t: DVec3) -> Node {
    Node {
        transform: DAffine3::from_translation(t),
        material: 0,
        name: None,
        json_path: "test".into(),
        kind,
    }
}

fn blend_of(spheres: &[(DVec3, f64)], k: f64) -> Node {
    let children = spheres
        .iter()
        .enumerate()
        .map(|(i, &(c, r))| {
            let mut n = node(NodeKind::Leaf(Shape::Sphere { radius: r }), c);
            n.material = i as u32;
            n
        })
        .collect();
    node(
        NodeKind::Smooth {
            op: SmoothOp::Blend,
            children,
            blend_radius: k,
        },
        DVec3::ZERO,
    )
}

/// The field without its boxes: the blend's own value everywhere (a bounded field answers
/// its box's distance far from it).
fn compile(n: &Node) -> Field {
    Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default())
        .expect("compiles")
        .without_bounds()
}

/// The blend of `a` by sorting: the `f` with `sum max(0, 1 - (a_i - f) / k)^2 = 1`, from the
/// active prefix of the sorted values whose quadratic's larger root lies below the next value.
fn blend_by_sorting(a: &[f64], k: f64) -> f64 {
    let mut b: Vec<f64> = a.to_vec();
    b.sort_by(f64::total_cmp);
    let m = b[0];
    let (mut s1, mut s2) = (0.0, 0.0);
    for n in 1..=b.len() {
        let v = b[n - 1] - m;
        s1 += v;
        s2 += v * v;
        let nf = n as f64;
        let x = (s1 + (s1 * s1 - nf * (s2 - k * k)).max(0.0).sqrt()) / nf;
        if n == b.len() || b[n] - m >= x {
            return m + x - k;
        }
    }
    unreachable!("the last prefix returns")
}

/// A small deterministic generator in [0, 1).
fn rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Spheres (centre, radius), a blend radius and points to evaluate at.
type Case = (Vec<(DVec3, f64)>, f64, Vec<DVec3>);

/// Random clusters of 1-12 spheres with random blend radii, and points around them.
fn cases(seed: u64, count: usize) -> Vec<Case> {
    let mut r = rng(seed);
    (0..count)
        .map(|_| {
            let n = 1 + (r() * 12.0) as usize;
            let spheres: Vec<(DVec3, f64)> = (0..n)
                .map(|_| {
                    let c = DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * 0.8;
                    (c, 0.05 + 0.2 * r())
                })
                .collect();
            let k = 0.01 + 0.4 * r();
            let points = (0..40)
                .map(|_| DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * 1.6)
                .collect();
            (spheres, k, points)
        })
        .collect()
}

fn values(spheres: &[(DVec3, f64)], p: DVec3) -> Vec<f64> {
    spheres.iter().map(|&(c, r)| (p - c).length() - r).collect()
}

#[test]
fn the_blend_is_the_sorted_solve_in_any_order_and_within_its_deficit() {
    for (spheres, k, points) in cases(1, 200) {
        let field = compile(&blend_of(&spheres, k));
        let mut reversed = spheres.clone();
        reversed.reverse();
        let field_reversed = compile(&blend_of(&reversed, k));
        for &p in &points {
            let a = values(&spheres, p);
            let want = blend_by_sorting(&a, k);
            let got = field.distance_f64(p);
            let scale = 1.0 + want.abs();
            assert!((got - want).abs() <= 1e-12 * scale, "{p}: {got} vs {want}");
            let other = field_reversed.distance_f64(p);
            assert!(
                (other - got).abs() <= 1e-12 * scale,
                "{p}: {other} vs {got}"
            );
            let m = a.iter().copied().fold(f64::INFINITY, f64::min);
            assert!(got <= m + 1e-15 * scale, "{p}: {got} above the minimum {m}");
            assert!(
                got >= m - blend_deficit(k, spheres.len()) - 1e-12 * scale,
                "{p}: {got} below the deficit bound from {m}"
            );
            // f32 agrees with the f64 value to f32 rounding.
            let g32 = f64::from(field.distance(p.as_vec3()));
            assert!((g32 - want).abs() <= 2e-6 * scale, "{p}: {g32} vs {want}");
        }
    }
}

#[test]
fn equal_children_reach_the_deficit_bound_and_a_lone_child_is_itself() {
    let p = DVec3::new(0.9, 0.2, -0.1);
    for n in [1usize, 2, 5, 17, 40] {
        let k = 0.3;
        let field = compile(&blend_of(&vec![(DVec3::ZERO, 0.5); n], k));
        let m = p.length() - 0.5;
        let got = field.distance_f64(p);
        let want = m - blend_deficit(k, n);
        assert!((got - want).abs() <= 1e-12, "{n}: {got} vs {want}");
    }
    // A child at least k above the nearest adds nothing: the value is the nearest child's.
    let field = compile(&blend_of(
        &[(DVec3::ZERO, 0.5), (DVec3::new(3.0, 0.0, 0.0), 0.5)],
        0.2,
    ));
    let p = DVec3::new(-0.7, 0.1, 0.0);
    assert_eq!(field.distance_f64(p), p.length() - 0.5);
}

#[test]
fn the_blend_is_one_lipschitz() {
    let mut r = rng(9);
    for (spheres, k, points) in cases(2, 120) {
        let field = compile(&blend_of(&spheres, k));
        for &p in &points {
            let q = p + DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * 0.2;
            let (fp, fq) = (field.distance_f64(p), field.distance_f64(q));
            assert!(
                (fp - fq).abs() <= (p - q).length() * (1.0 + 1e-9) + 1e-12,
                "{p} {q}: {fp} {fq}"
            );
        }
        // The slope by central differences: at most 1, and 1 where one child rules.
        for p in &points {
            let h = 1e-6;
            let d = |e: DVec3| {
                (field.distance_f64(*p + e * h) - field.distance_f64(*p - e * h)) / (2.0 * h)
            };
            let slope = DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z)).length();
            assert!(slope <= 1.0 + 1e-6, "{p}: slope {slope}");
        }
    }
}

#[test]
fn the_blend_never_falls_when_a_child_rises() {
    let mut r = rng(5);
    for _ in 0..2000 {
        let n = 2 + (r() * 8.0) as usize;
        let k = 0.05 + r();
        let a: Vec<f64> = (0..n).map(|_| r() * k * 1.5).collect();
        let base = blend_by_sorting(&a, k);
        let mut up = a.clone();
        let i = (r() * n as f64) as usize % n;
        up[i] += r() * 0.5 * k;
        assert!(blend_by_sorting(&up, k) >= base - 1e-15);
        // The field computes the same function of the children's values: spheres of these
        // radii around one point, read from their common centre.
        let spheres: Vec<(DVec3, f64)> = a.iter().map(|&v| (DVec3::ZERO, 1.0 - v)).collect();
        let field = compile(&blend_of(&spheres, k));
        let got = field.distance_f64(DVec3::ZERO) + 1.0;
        assert!((got - base).abs() <= 1e-12, "{got} vs {base}");
    }
}

#[test]
fn eight_lanes_are_eight_single_queries_bit_for_bit_with_the_nearest_material() {
    for (spheres, k, points) in cases(3, 60) {
        let field = compile(&blend_of(&spheres, k));
        for chunk in points.chunks_exact(8) {
            let p: [Vec3; 8] = std::array::from_fn(|i| chunk[i].as_vec3());
            let (d, m) = field.distance_material_x8(p);
            for i in 0..8 {
                let (one, mat) = field.distance_material(p[i]);
                assert_eq!(d[i].to_bits(), one.to_bits(), "{}", p[i]);
                assert_eq!(m[i], mat);
                // The nearest child's material.
                let a = values(&spheres, p[i].as_dvec3());
                let nearest = (0..a.len())
                    .min_by(|&x, &y| a[x].total_cmp(&a[y]))
                    .expect("children");
                let gap = a
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != nearest)
                    .map(|(_, v)| v - a[nearest])
                    .fold(f64::INFINITY, f64::min);
                if gap > 1e-4 {
                    assert_eq!(mat, nearest as u32, "{}", p[i]);
                }
            }
        }
    }
}

#[test]
fn more_children_near_a_point_than_the_solve_buffers_give_the_same_blend() {
    // 70 spheres around one point, all within k of each other there: the solve reads the
    // children again in each pass instead of its buffer.
    let mut r = rng(11);
    let spheres: Vec<(DVec3, f64)> = (0..70)
        .map(|_| {
            let c = DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * 0.05;
            (c, 0.3)
        })
        .collect();
    let k = 0.2;
    let field = compile(&blend_of(&spheres, k));
    for i in 0..50 {
        let a = f64::from(i) * 0.37;
        let p = DVec3::new(a.cos(), (a * 1.3).sin(), a.sin()) * (0.2 + 0.01 * f64::from(i));
        let want = blend_by_sorting(&values(&spheres, p), k);
        let got = field.distance_f64(p);
        assert!(
            (got - want).abs() <= 1e-12 * (1.0 + want.abs()),
            "{p}: {got} vs {want}"
        );
        let g32 = f64::from(field.distance(p.as_vec3()));
        assert!((g32 - want).abs() <= 1e-5, "{p}: {g32} vs {want}");
    }
}

#[test]
fn a_nested_blend_is_kept_as_written() {
    // blend(blend(a, b), c) is not blend(a, b, c): the scene keeps the nesting.
    let s = |x: f64| (DVec3::new(x, 0.0, 0.0), 0.3);
    let inner = blend_of(&[s(-0.25), s(0.25)], 0.3);
    let mut outer = blend_of(&[s(0.0)], 0.3);
    if let NodeKind::Smooth { children, .. } = &mut outer.kind {
        children.insert(0, inner);
    }
    let nested = compile(&outer);
    let flat = compile(&blend_of(&[s(-0.25), s(0.25), s(0.0)], 0.3));
    let p = DVec3::new(0.0, 0.45, 0.0);
    let a = values(&[s(-0.25), s(0.25)], p);
    let want = blend_by_sorting(&[blend_by_sorting(&a, 0.3), p.length() - 0.3], 0.3);
    assert!((nested.distance_f64(p) - want).abs() < 1e-12);
    assert!((nested.distance_f64(p) - flat.distance_f64(p)).abs() > 1e-4);
}
