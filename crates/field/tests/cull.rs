//! Restricting a field to a bundle of rays ([`Field::restrict_to`]): sphere tracing through
//! the restricted field stays safe along every ray of the bundle (no step passes the first
//! surface the ray meets among *all* objects), the values are never below the whole
//! field's, and equal to them wherever the nearest object was kept.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::{Field, FieldOptions, RayCone, Restricted};
use marchmesh_scene::{Node, NodeKind, Shape};
use proptest::prelude::*;

/// `n` spheres (radius `r`) at the given centres, plus a box and a ground plane, under one
/// union (nested so the top level is a union of unions, as scenes with groups compile).
fn scene(centres: &[DVec3], r: f64) -> (Field, Vec<(DVec3, f64)>) {
    let leaf = |kind: NodeKind, t: DVec3| Node {
        transform: DAffine3::from_translation(t),
        material: 0,
        name: None,
        json_path: "test".into(),
        kind,
    };
    let mut children: Vec<Node> = centres
        .iter()
        .map(|&c| leaf(NodeKind::Leaf(Shape::Sphere { radius: r }), c))
        .collect();
    children.push(leaf(
        NodeKind::Leaf(Shape::Plane {
            normal: DVec3::Y,
            offset: 0.0,
        }),
        DVec3::new(0.0, -3.0, 0.0),
    ));
    let root = leaf(NodeKind::Union(children), DVec3::ZERO);
    let f =
        Field::compile_node(&root, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles");
    (f, centres.iter().map(|&c| (c, r)).collect())
}

/// First hit of the ray with any sphere or the ground plane y = -3 (f64 closed forms).
fn first_hit(dir: DVec3, spheres: &[(DVec3, f64)]) -> f64 {
    let mut best = if dir.y < 0.0 {
        -3.0 / dir.y
    } else {
        f64::INFINITY
    };
    for &(c, r) in spheres {
        let b = dir.dot(c);
        let disc = b * b - (c.length_squared() - r * r);
        if disc >= 0.0 {
            let t = b - disc.sqrt();
            if t > 0.0 {
                best = best.min(t);
            }
        }
    }
    best
}

fn grid(n: usize, seed: u64) -> Vec<DVec3> {
    let mut s = seed | 1;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|i| {
            let side = (n as f64).sqrt().ceil() as usize;
            let (x, y) = ((i % side) as f64, (i / side) as f64);
            DVec3::new(
                (x + 0.5) / side as f64 * 8.0 - 4.0,
                (y + 0.5) / side as f64 * 6.0 - 3.0,
                6.0 + 4.0 * rnd(),
            )
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn restricted_steps_never_pass_the_first_surface(
        seed in any::<u64>(),
        row in -0.4f32..0.4,
        start in -0.5f32..0.4,
        width in 0.001f32..0.2,
    ) {
        let centres = grid(400, seed);
        let (field, spheres) = scene(&centres, 0.12);
        let dirs: Vec<Vec3> = (0..32)
            .map(|k| Vec3::new(start + width * k as f32 / 31.0, row, 1.0).normalize())
            .collect();
        let cone = RayCone::around(Vec3::ZERO, dirs.iter().copied(), 1e3, 0.0, 1e-6)
            .expect("a narrow bundle");
        let mut r = Restricted::default();
        field.restrict_to(&cone, &mut r);
        prop_assert!(r.node_count() < 400, "kept {} of ~800 nodes", r.node_count());
        for d in &dirs {
            let t_hit = first_hit(d.as_dvec3(), &spheres);
            let t_end = t_hit.min(40.0);
            for k in 0..64 {
                let t = t_end * k as f64 / 64.0;
                let p = (d.as_dvec3() * t).as_vec3();
                let kept = field.restricted_distance(&r, p);
                let whole = field.distance(p);
                // Never below the whole field (it minimises over fewer objects) ...
                prop_assert!(kept >= whole - 1e-5, "t {t}: kept {kept} < whole {whole}");
                // ... and never a step past the first surface on the ray.
                prop_assert!(
                    f64::from(kept) <= t_hit - t + 1e-4,
                    "t {t}: kept {kept} steps past the hit at {t_hit}"
                );
                let x8 = field.restricted_distance_x8(&r, [p; 8]);
                prop_assert_eq!(x8[3], kept);
            }
        }
    }
}

#[test]
fn a_bundle_that_sees_nothing_gets_an_empty_field_and_a_wide_one_everything() {
    let (field, _) = scene(&grid(64, 7), 0.1);
    let mut r = Restricted::default();
    // Straight up: no sphere, and the ground plane is behind.
    let up = [Vec3::new(0.0, 1.0, 0.01), Vec3::new(0.01, 1.0, 0.0)];
    let cone = RayCone::around(Vec3::ZERO, up.into_iter(), 1e3, 0.0, 0.0).expect("narrow");
    field.restrict_to(&cone, &mut r);
    // The plane's box is unbounded, so it stays; every sphere is dropped.
    assert!(r.node_count() <= 2, "kept {}", r.node_count());
    assert!(r.dropped() >= 64);
    // Looking at the grid through a wide pyramid keeps every sphere.
    let wide = [
        Vec3::new(-1.0, -1.0, 1.0),
        Vec3::new(1.0, -1.0, 1.0),
        Vec3::new(-1.0, 1.0, 1.0),
        Vec3::new(1.0, 1.0, 1.0),
    ];
    let cone = RayCone::around(Vec3::ZERO, wide.into_iter(), 1e3, 0.0, 0.0).expect("45 deg");
    field.restrict_to(&cone, &mut r);
    assert_eq!(r.dropped(), 0);
}

#[test]
fn a_narrow_bundle_over_a_hierarchy_gets_a_flat_tape() {
    // 400 spheres compile to a union hierarchy (groups of at most 8 under median splits);
    // a bundle of one pixel row keeps a few dozen of them, flattened into one union.
    let centres = grid(400, 11);
    let (field, spheres) = scene(&centres, 0.12);
    assert!(!field.has_tape());
    let dirs: Vec<Vec3> = (0..32)
        .map(|k| Vec3::new(-0.3 + 0.02 * k as f32 / 31.0, 0.05, 1.0).normalize())
        .collect();
    let cone = RayCone::around(Vec3::ZERO, dirs.iter().copied(), 1e3, 0.0, 1e-6).expect("narrow");
    let mut r = Restricted::default();
    field.restrict_to(&cone, &mut r);
    assert!(r.is_taped(), "{} nodes kept", r.node_count());
    assert!(
        r.node_count() >= 3 && r.dropped() > 300,
        "kept {}",
        r.node_count()
    );
    // The flat union is the exact minimum over the kept spheres: on the rays it equals the
    // whole field wherever the nearest sphere lies in the bundle's reach.
    for d in &dirs {
        let t_hit = first_hit(d.as_dvec3(), &spheres);
        for k in 0..32 {
            let t = t_hit.min(20.0) * k as f64 / 32.0;
            let p = d.as_dvec3() * t;
            let kept = f64::from(field.restricted_distance(&r, p.as_vec3()));
            let exact = spheres
                .iter()
                .map(|&(c, rad)| (p - c).length() - rad)
                .fold(p.y + 3.0, f64::min);
            assert!(kept >= exact - 1e-5, "t {t}: kept {kept} < exact {exact}");
            // Lanes (the tape) and the scalar interpreter agree bit for bit.
            assert_eq!(
                field.restricted_distance_x8(&r, [p.as_vec3(); 8])[5],
                kept as f32
            );
        }
    }
}
