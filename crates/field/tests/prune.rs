//! Pruning per region (`marchmesh_field::prune`): the pruned cells give the whole program's
//! value bit for bit wherever they hold a program (within the stated error when a smooth
//! union's fold may be cut), and elsewhere a positive lower bound of the distance to the
//! surfaces; on random trees of every operator.

use glam::{DAffine3, DVec3, Vec3};
use marchmesh_field::prune::prune;
use marchmesh_field::{Field, FieldOptions};
use marchmesh_scene::{Node, NodeKind, Shape, SmoothOp};
use proptest::prelude::*;

fn node(kind: NodeKind, t: DVec3) -> Node {
    Node {
        transform: DAffine3::from_translation(t),
        material: 0,
        name: None,
        json_path: "test".into(),
        kind,
    }
}

fn sphere(r: f64, c: DVec3) -> Node {
    node(NodeKind::Leaf(Shape::Sphere { radius: r }), c)
}

/// A random walk of `n` spheres of radius 0.032, steps of 0.04 (the sculpted molecule).
fn molecule(n: usize, seed: u64, k: f64) -> Node {
    let mut rng = seed;
    let mut next = move || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut c = DVec3::ZERO;
    let children = (0..n)
        .map(|_| {
            let d = DVec3::new(next(), next(), next()).normalize_or_zero();
            c += d * 0.04;
            if c.length() > 0.3 {
                c -= d * 0.08;
            }
            sphere(0.032, c)
        })
        .collect();
    node(
        NodeKind::Smooth {
            op: SmoothOp::Union,
            children,
            blend_radius: k,
        },
        DVec3::ZERO,
    )
}

/// [`molecule`] blended at once ([`SmoothOp::Blend`]) instead of folded.
fn blend_molecule(n: usize, seed: u64, k: f64) -> Node {
    let mut mol = molecule(n, seed, k);
    if let NodeKind::Smooth { op, .. } = &mut mol.kind {
        *op = SmoothOp::Blend;
    }
    mol
}

fn compile(n: &Node) -> Field {
    Field::compile_node(n, DAffine3::IDENTITY, &FieldOptions::default()).expect("compiles")
}

/// Points on a lattice over the box grown by 0.2, jittered.
fn probes(n: usize) -> Vec<DVec3> {
    let mut out = Vec::new();
    for i in 0..n * n * n {
        let (x, y, z) = (i % n, i / n % n, i / (n * n));
        let f = |v: usize, j: f64| -0.5 + (v as f64 + 0.5 + 0.37 * j) / n as f64;
        out.push(DVec3::new(f(x, 0.3), f(y, -0.7), f(z, 0.1)));
    }
    out
}

fn check_cells(n: &Node, depth: u32) {
    let whole = compile(n);
    let mut cells = compile(n);
    let stats = cells.build_cells(depth, 0.0).expect("bounded, no meshes");
    assert!(stats.program_cells > 0);
    assert!(stats.subset_cells > 0, "{stats:?}");
    let mut exact = 0;
    for p in probes(24) {
        // f64: pruned programs where they exist, the whole program elsewhere: identical.
        assert_eq!(
            whole.distance_f64(p).to_bits(),
            cells.distance_f64(p).to_bits(),
            "{p}"
        );
        let (w, c) = (whole.distance(p.as_vec3()), cells.distance(p.as_vec3()));
        if w.to_bits() == c.to_bits() {
            exact += 1;
        } else {
            // A far cell or outside the box: a bound of the distance with the field's sign
            // (the whole field is a bound of it too, so only the signs can be compared).
            assert!(
                c != 0.0 && (c > 0.0) == (w > 0.0),
                "{p}: cells {c}, whole {w}"
            );
            let b = cells.distance_bound_f64(p);
            assert!(
                (b > 0.0) == (c > 0.0) && b.abs() <= f64::from(c.abs()) + 1e-6,
                "{p}: {b} vs {c}"
            );
        }
        // Segment steps: the same value where the cells answer exactly (a segment within
        // one program or subset cell, or the whole program).
        let dir = Vec3::new(0.3, -0.8, 0.52).normalize();
        let (sw, _) = whole.segment_step(p.as_vec3(), dir, 1e-3);
        let (sc, step) = cells.segment_step(p.as_vec3(), dir, 1e-3);
        assert_eq!(sw.to_bits(), sc.to_bits(), "{p}");
        assert!(step >= 0.0);
        // Materials come from the whole program outside program cells.
        assert_eq!(
            whole.distance_material(p.as_vec3()).1,
            cells.distance_material(p.as_vec3()).1
        );
    }
    assert!(exact > 0);
    // Eight lanes: per lane what the single query gives.
    let pts: Vec<Vec3> = probes(8).iter().map(|p| p.as_vec3()).collect();
    for chunk in pts.chunks_exact(8) {
        let p: [Vec3; 8] = std::array::from_fn(|i| chunk[i]);
        let lanes = cells.distance_x8(p);
        let (dm, mm) = cells.distance_material_x8(p);
        for i in 0..8 {
            assert_eq!(lanes[i].to_bits(), cells.distance(p[i]).to_bits());
            assert_eq!(mm[i], whole.distance_material(p[i]).1);
            let _ = dm;
        }
    }
}

#[test]
fn a_pruned_molecule_is_the_whole_molecule_where_surfaces_are() {
    check_cells(&molecule(300, 7, 0.026), 5);
}

#[test]
fn a_pruned_blend_molecule_is_the_whole_molecule_where_surfaces_are() {
    let mol = blend_molecule(300, 7, 0.026);
    check_cells(&mol, 5);
    // Its subset cells list the children near each finest cell: shorter lists, the same bits.
    let stats = compile(&mol).build_cells(5, 0.0).expect("built");
    assert!(stats.fine_lists > 0, "{stats:?}");
    assert!(stats.fine_children < stats.subset_children, "{stats:?}");
}

#[test]
fn the_hard_true_distance_bounds_the_far_cells() {
    // A hard union of spheres: its field is the exact distance outside, so the far bound
    // must stay below it there, and have its sign inside.
    let m = molecule(200, 3, 0.026);
    let NodeKind::Smooth {
        op: SmoothOp::Union,
        children,
        ..
    } = m.kind
    else {
        unreachable!()
    };
    let centres: Vec<DVec3> = children.iter().map(|c| c.transform.translation).collect();
    let hard = node(NodeKind::Union(children), DVec3::ZERO);
    let mut f = compile(&hard);
    f.build_cells(5, 0.0).expect("cells");
    for p in probes(20) {
        let exact = centres
            .iter()
            .map(|c| (p - *c).length() - 0.032)
            .fold(f64::INFINITY, f64::min);
        let b = f.distance_bound_f64(p);
        if exact > 0.0 {
            assert!(
                b <= exact + 1e-9,
                "{p}: bound {b} above the distance {exact}"
            );
            assert!(f64::from(f.distance(p.as_vec3())) <= exact + 1e-5);
        } else {
            assert!(b <= 0.0, "{p}: bound {b} inside");
        }
    }
}

#[test]
fn a_smooth_fold_keeps_what_comes_before_a_near_child() {
    // Two far children then a near one: dropping the far ones would change the fold (the
    // pair lowers itself by k/4 into the near child's blend range when they are within
    // 2k); the pruner must keep them where that happens.
    let k = 1.0;
    let n = node(
        NodeKind::Smooth {
            op: SmoothOp::Union,
            children: vec![
                sphere(0.1, DVec3::new(1.1, 0.0, 0.0)),
                sphere(0.1, DVec3::new(1.1, 0.0, 0.0)),
                sphere(0.1, DVec3::ZERO),
            ],
            blend_radius: k,
        },
        DVec3::ZERO,
    );
    let whole = compile(&n);
    let prog = whole_program(&n);
    for r in [0.01, 0.1, 0.5] {
        let p = DVec3::new(0.1, 0.0, 0.0);
        let pruned = prune(&prog, &[], p, r, 0.0);
        let got = eval64(&pruned.program, p);
        assert_eq!(got.to_bits(), whole.distance_f64(p).to_bits(), "r = {r}");
        assert!(pruned.lo <= got && got <= pruned.hi);
    }
}

fn whole_program(n: &Node) -> marchmesh_field::program::Program<f64> {
    compile(n).program_f64().clone()
}

fn eval64(p: &marchmesh_field::program::Program<f64>, q: DVec3) -> f64 {
    p.eval::<f64, false>(marchmesh_field::V3::new(q.x, q.y, q.z), &[])
        .0
}

fn arb_tree() -> impl Strategy<Value = Node> {
    let leaf = (0.02f64..0.2, -0.4f64..0.4, -0.4f64..0.4, -0.4f64..0.4)
        .prop_map(|(r, x, y, z)| sphere(r, DVec3::new(x, y, z)));
    leaf.prop_recursive(4, 48, 8, |inner| {
        (
            0u8..7,
            proptest::collection::vec(inner, 2..8),
            0.005f64..0.2,
            -0.1f64..0.1,
        )
            .prop_map(|(op, children, k, shift)| {
                let kind = match op {
                    0 => NodeKind::Union(children),
                    1 => NodeKind::Intersection(children),
                    2 => NodeKind::Subtraction(children),
                    3 => NodeKind::Smooth {
                        op: SmoothOp::Intersection,
                        children,
                        blend_radius: k,
                    },
                    4 => NodeKind::Smooth {
                        op: SmoothOp::Subtraction,
                        children,
                        blend_radius: k,
                    },
                    5 => NodeKind::Smooth {
                        op: SmoothOp::Union,
                        children,
                        blend_radius: k,
                    },
                    _ => NodeKind::Smooth {
                        op: SmoothOp::Blend,
                        children,
                        blend_radius: k,
                    },
                };
                node(kind, DVec3::new(shift, -shift, 0.5 * shift))
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_trees_prune_exactly(tree in arb_tree(), depth in 1u32..5) {
        let whole = compile(&tree);
        let mut cells = compile(&tree);
        if cells.build_cells(depth, 0.0).is_none() {
            return Ok(());
        }
        for p in probes(10) {
            prop_assert_eq!(whole.distance_f64(p).to_bits(), cells.distance_f64(p).to_bits());
            let (w, c) = (whole.distance(p.as_vec3()), cells.distance(p.as_vec3()));
            prop_assert!(w.to_bits() == c.to_bits() || (c != 0.0 && (c > 0.0) == (w > 0.0)), "{} vs {}", w, c);
        }
    }
}

/// Largest `|cells - whole|` (f64) over the probes where the cells hold a program, and
/// whether every far answer has the whole field's sign.
fn deviation(whole: &Field, cells: &Field, points: &[DVec3]) -> f64 {
    let mut worst = 0.0f64;
    for &p in points {
        let (w, c) = (whole.distance_f64(p), cells.distance_f64(p));
        worst = worst.max((w - c).abs());
        let b = cells.distance_bound_f64(p);
        assert!(
            b == c || (b != 0.0 && (b > 0.0) == (w > 0.0) && b.abs() <= w.abs() + 1e-6),
            "{p}: far bound {b}, whole {w}"
        );
    }
    worst
}

#[test]
fn a_cut_fold_drops_the_start_of_an_approach_within_its_error() {
    // Spheres approaching the origin in steps of 0.06, below a blend radius of 0.1: each
    // child changes the running blend, so the exact pruner keeps all of them; but each lies
    // below the prefix, which then reaches the result only through a derivative of about
    // 0.23, so cutting the first half changes the value by far less than 1e-6.
    let k = 0.1;
    let children = (0..17)
        .map(|i| sphere(0.05, DVec3::new(1.0 - 0.06 * f64::from(i), 0.0, 0.0)))
        .collect();
    let n = node(
        NodeKind::Smooth {
            op: SmoothOp::Union,
            children,
            blend_radius: k,
        },
        DVec3::ZERO,
    );
    let prog = whole_program(&n);
    let (centre, r) = (DVec3::ZERO, 1e-4);
    let exact = prune(&prog, &[], centre, r, 0.0);
    let cut = prune(&prog, &[], centre, r, 1e-6);
    assert_eq!(
        exact.program.instrs.len(),
        prog.instrs.len(),
        "exact keeps the chain"
    );
    assert!(
        cut.program.instrs.len() * 3 < exact.program.instrs.len() * 2,
        "cut keeps {} of {} nodes",
        cut.program.instrs.len(),
        exact.program.instrs.len()
    );
    for q in [
        centre,
        DVec3::new(5e-5, 0.0, 0.0),
        DVec3::new(0.0, -7e-5, 3e-5),
    ] {
        let (w, c) = (eval64(&prog, q), eval64(&cut.program, q));
        assert!((w - c).abs() <= 1e-6, "{q}: cut {c}, whole {w}");
        assert!(cut.lo <= w && w <= cut.hi);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_trees_prune_within_the_error(tree in arb_tree(), depth in 1u32..5, exp in 3i32..9) {
        let whole = compile(&tree);
        let mut cells = compile(&tree);
        let rel = 10f64.powi(-exp);
        if cells.build_cells(depth, rel).is_none() {
            return Ok(());
        }
        let (lo, hi) = whole.bounds().expect("bounded");
        let max_error = rel * (hi - lo).max_element();
        let worst = deviation(&whole, &cells, &probes(10));
        prop_assert!(worst <= max_error * (1.0 + 1e-9) + 1e-15, "{} over {}", worst, max_error);
    }
}

/// A left-deep chain of `levels` smooth intersections: every cell the surface crosses keeps
/// nearly the whole chain, so an unbudgeted octree reads the whole program at every node.
fn intersection_chain(levels: usize) -> Node {
    let mut n = sphere(0.5, DVec3::ZERO);
    for _ in 0..levels {
        n = node(
            NodeKind::Smooth {
                op: SmoothOp::Intersection,
                children: vec![n, sphere(0.6, DVec3::new(0.3, 0.0, 0.0))],
                blend_radius: 0.05,
            },
            DVec3::ZERO,
        );
    }
    n
}

#[test]
fn the_octree_build_stays_near_its_work_budget_and_never_fails() {
    use marchmesh_field::prune::{Cells, PruneIndex};
    // A molecule prunes well: its octree is built within the budget.
    let mut m = compile(&molecule(300, 7, 0.026));
    let nodes = m.node_count();
    let stats = m.build_cells(6, 0.0).expect("a molecule is bounded");
    assert!(stats.pruned_nodes > 0 && stats.pruned_nodes <= Cells::max_work(nodes));
    // A deep chain reads its whole program at every octree node: the refinement stops
    // where the next level would not fit, and the last level settles its cells anyway
    // (at most about the budget again), with the whole field's values.
    let chain = intersection_chain(300);
    let whole = whole_program(&chain);
    let nodes = whole.instrs.len();
    let f = compile(&chain);
    let (lo, hi) = f.bounds().expect("bounded");
    let index = PruneIndex::build(&whole);
    let budget = 1 << 17;
    let cells =
        Cells::build_within(&whole, &index, &[], (lo, hi), 0.01, 6, 0.0, budget).expect("built");
    let spent = cells.stats().pruned_nodes;
    assert!(spent <= 2 * budget + 4 * nodes, "{:?}", cells.stats());
    // Its cells give the whole chain's values.
    for p in probes(6) {
        let v = marchmesh_field::V3::new(p.x, p.y, p.z);
        let (w, _) = whole.eval::<f64, false>(v, &[]);
        let (c, _) = cells.eval_f64::<false>(p, &whole, &[]);
        assert_eq!(w.to_bits(), c.to_bits(), "{p}");
    }
}

/// Restricting through the child trees ([`prune_indexed`]) gives the whole program's value
/// at every point of the ball, bit for bit with no error allowed, on large smooth unions,
/// hard unions and subtractions (whose children the trees read); on a long chain (a walk
/// that does not come back) it reads a small part of the children.
#[test]
fn an_indexed_restriction_is_the_whole_program_in_its_ball() {
    use marchmesh_field::prune::{PruneIndex, prune_indexed};
    let blob = molecule(600, 5, 0.026);
    let NodeKind::Smooth { children, .. } = blob.kind.clone() else {
        unreachable!()
    };
    let hard = node(NodeKind::Union(children.clone()), DVec3::ZERO);
    let mut carved_children = vec![sphere(0.35, DVec3::ZERO)];
    carved_children.extend(children.iter().take(300).cloned());
    let carved = node(
        NodeKind::Subtraction(carved_children),
        DVec3::new(0.01, 0.0, 0.0),
    );
    // A helix of 600 spheres, 0.04 apart, over about 24 units.
    let helix_at = |i: usize| {
        let a = i as f64 * 0.1;
        DVec3::new(0.3 * a.cos(), 0.3 * a.sin(), i as f64 * 0.03)
    };
    let helix = node(
        NodeKind::Smooth {
            op: SmoothOp::Union,
            children: (0..600).map(|i| sphere(0.032, helix_at(i))).collect(),
            blend_radius: 0.026,
        },
        DVec3::ZERO,
    );
    let near_helix: Vec<DVec3> = (0..40)
        .map(|i| helix_at(i * 15 + 3) + DVec3::new(0.01, -0.03, 0.02))
        .collect();
    for (tree, points) in [
        (&blob, probes(7)),
        (&hard, probes(7)),
        (&carved, probes(7)),
        (&helix, near_helix.clone()),
    ] {
        let prog = whole_program(tree);
        let index = PruneIndex::build(&prog);
        for (i, centre) in points.into_iter().enumerate() {
            let radius = [0.0, 0.005, 0.02, 0.08][i % 4];
            let linear = prune(&prog, &[], centre, radius, 0.0);
            let indexed = prune_indexed(&prog, &index, &[], centre, radius, 0.0);
            for dir in [DVec3::ZERO, DVec3::X, -DVec3::Y, DVec3::ONE.normalize()] {
                let q = centre + dir * radius * 0.999;
                let w = eval64(&prog, q);
                assert_eq!(eval64(&indexed.program, q).to_bits(), w.to_bits(), "{q}");
                assert_eq!(eval64(&linear.program, q).to_bits(), w.to_bits(), "{q}");
                assert!(indexed.lo <= w && w <= indexed.hi, "{q}: {w} outside");
            }
        }
    }
    // An exact restriction keeps a walk's whole approach to the ball (each sphere changes
    // the running blend there); within an error, over a ball smaller than a step of the
    // walk, the approach is cut, and the trees read a small part of the children.
    let prog = whole_program(&helix);
    let index = PruneIndex::build(&prog);
    let mut read = 0;
    for (i, &centre) in near_helix.iter().enumerate() {
        let radius = [0.0, 0.002, 0.005][i % 3];
        let indexed = prune_indexed(&prog, &index, &[], centre, radius, 1e-6);
        read += indexed.work;
        for dir in [DVec3::ZERO, DVec3::X, -DVec3::Y] {
            let q = centre + dir * radius * 0.999;
            assert!((eval64(&indexed.program, q) - eval64(&prog, q)).abs() <= 1e-6);
        }
    }
    assert!(
        read * 5 < near_helix.len() * prog.instrs.len(),
        "read {read} over {} balls of {} nodes",
        near_helix.len(),
        prog.instrs.len()
    );
}

/// A field restricted to a small ball ([`Field::restricted_to_ball`]) reads a handful of a
/// large molecule's children and gives the whole field's f32 value at every point of the
/// ball, within the error it was given (here exact: 0).
#[test]
fn a_ball_restriction_is_small_and_agrees_inside_the_ball() {
    let whole = compile(&molecule(400, 11, 0.026));
    let nodes = whole.node_count();
    let probes = probes(8);
    let mut smallest = usize::MAX;
    for (i, &centre) in probes.iter().enumerate() {
        let radius = 0.02 + 0.01 * (i % 3) as f64;
        let ball = whole.restricted_to_ball(centre, radius, 0.0);
        smallest = smallest.min(ball.node_count());
        // Eight points inside the ball: on its axes, at its rim and at the centre.
        let at = |j: usize| {
            let dir = [
                DVec3::X,
                DVec3::Y,
                DVec3::Z,
                -DVec3::X,
                -DVec3::Y,
                -DVec3::Z,
                DVec3::ONE.normalize(),
                DVec3::ZERO,
            ][j];
            (centre + dir * radius * 0.999).as_vec3()
        };
        let points: [Vec3; 8] = std::array::from_fn(at);
        let inside = whole.ball_distance_x8(&ball, points);
        let expected = whole.distance_x8(points);
        for j in 0..8 {
            assert_eq!(
                inside[j].to_bits(),
                expected[j].to_bits(),
                "{:?} in the ball at {centre}, radius {radius}",
                points[j]
            );
        }
    }
    assert!(
        smallest * 10 < nodes,
        "the smallest restriction holds {smallest} of {nodes} nodes"
    );
}

/// One material on every node is known without evaluating; two are not.
#[test]
fn a_single_material_is_known_without_evaluating() {
    assert_eq!(compile(&molecule(20, 3, 0.026)).single_material(), Some(0));
    let mut two = molecule(20, 3, 0.026);
    if let NodeKind::Smooth { children, .. } = &mut two.kind {
        children[5].material = 2;
    }
    assert_eq!(compile(&two).single_material(), None);
}

/// A fold over kept children that scans them eight at a time (`KidBlock`) gives bit for
/// bit what the child-by-child fold gives, value and material, in one lane and eight, on
/// random subsequences of a molecule's children at points near and far from its surface,
/// many of them far from most children (where the scan rules children out).
#[test]
fn a_fold_scanning_blocks_is_the_fold_child_by_child() {
    use marchmesh_field::V3;
    use marchmesh_field::lane::F32x8;
    use marchmesh_field::program::{FOLD_BLOCK, KidBlock};
    let mut mol = molecule(400, 11, 0.026);
    if let NodeKind::Smooth { children, .. } = &mut mol.kind {
        for (i, c) in children.iter_mut().enumerate() {
            c.material = (i % 3) as u32;
        }
    }
    let p32 = whole_program(&mol).cast::<f32>();
    let spheres = p32.sphere_table::<f32>();
    let root_end = p32.instrs[0].end;
    let mut all = Vec::new();
    let mut j = 1;
    while j < root_end {
        all.push(j);
        j = p32.instrs[j as usize].end;
    }
    let mut rng = 7u64;
    let mut next = move || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut far_children = 0usize;
    for round in 0..40 {
        // Every child, or a random subsequence of them (a cell's kept children).
        let keep = [1.0f32, 0.5, 0.1][round % 3];
        let kids: Vec<u32> = all
            .iter()
            .enumerate()
            .filter(|&(i, _)| i == 0 || next() < keep)
            .map(|(_, &j)| j)
            .collect();
        let blocks = KidBlock::table(&spheres, &kids);
        assert_eq!(blocks.len(), kids.len().div_ceil(FOLD_BLOCK));
        for _ in 0..100 {
            // Near the walk (its spheres lie within 0.35 of the origin) and beyond it; the
            // eight lanes spread or close together.
            let spread = [0.2f32, 0.4, 1.5][(next() * 3.0) as usize % 3];
            let centre = [next(), next(), next()].map(|v| (2.0 * v - 1.0) * spread);
            let gap = [0.001f32, 0.02, 0.3][(next() * 3.0) as usize % 3];
            let lanes: [[f32; 3]; 8] =
                std::array::from_fn(|_| centre.map(|v| v + (2.0 * next() - 1.0) * gap));
            for l in lanes {
                let v = V3::new(l[0], l[1], l[2]);
                let a = p32.eval_root_subset::<f32, true>(&kids, &spheres, &blocks, v, &[]);
                let b = p32.eval_root_subset::<f32, true>(&kids, &spheres, &[], v, &[]);
                assert_eq!((a.0.to_bits(), a.1), (b.0.to_bits(), b.1), "{l:?}");
                // Without the material, spheres are read from the blocks (or the table)
                // alone, not from their nodes.
                for (table, blocks) in [(&spheres[..], &blocks[..]), (&spheres[..], &[][..])] {
                    let a = p32.eval_root_subset::<f32, false>(&kids, table, blocks, v, &[]);
                    assert_eq!(a.0.to_bits(), b.0.to_bits(), "{l:?}");
                }
                let a = p32.eval_root_subset::<f32, false>(&kids, &[], &[], v, &[]);
                assert_eq!(a.0.to_bits(), b.0.to_bits(), "{l:?}");
            }
            let v8 = V3::new(
                F32x8(lanes.map(|l| l[0])),
                F32x8(lanes.map(|l| l[1])),
                F32x8(lanes.map(|l| l[2])),
            );
            let a = p32.eval_root_subset::<F32x8, true>(&kids, &spheres, &blocks, v8, &[]);
            let b = p32.eval_root_subset::<F32x8, true>(&kids, &spheres, &[], v8, &[]);
            assert_eq!(a.0.0.map(f32::to_bits), b.0.0.map(f32::to_bits));
            assert_eq!(a.1, b.1);
            for blocks in [&blocks[..], &[][..]] {
                let a = p32.eval_root_subset::<F32x8, false>(&kids, &spheres, blocks, v8, &[]);
                assert_eq!(a.0.0.map(f32::to_bits), b.0.0.map(f32::to_bits));
            }
            let v = V3::new(lanes[0][0], lanes[0][1], lanes[0][2]);
            let whole = p32.eval::<f32, false>(v, &[]).0;
            for b in &blocks {
                far_children += b.near(lanes[0], 0.0, whole + 0.1, 0.026).count_zeros() as usize;
            }
        }
    }
    assert!(far_children > 10_000, "{far_children} far children");
}

#[test]
fn a_lone_root_cell_lists_every_child_and_gives_the_whole_values() {
    lone_root_cell(molecule(300, 11, 0.026));
}

#[test]
fn a_lone_root_cell_of_a_blend_gives_the_whole_values() {
    // Single points read the spheres eight at a time, eight lanes skip blocks of far ones.
    lone_root_cell(blend_molecule(300, 11, 0.026));
}

fn lone_root_cell(mol: Node) {
    // A work budget of 0 settles the octree's root: one subset cell over the whole box,
    // no far cells, no index of finest cells.
    let whole = compile(&mol);
    let mut cells = compile(&mol);
    let stats = cells
        .build_cells_within(6, 0.0, 0, false)
        .expect("a molecule is bounded");
    assert_eq!(
        (stats.program_cells, stats.subset_cells, stats.far_cells),
        (1, 1, 0),
        "{stats:?}"
    );
    assert!(stats.subset_children <= 300 && stats.subset_children > 0);
    let (lo, hi) = whole.bounds().expect("bounded");
    let mut inside = 0;
    for p in probes(16) {
        let (w, c) = (whole.distance(p.as_vec3()), cells.distance(p.as_vec3()));
        assert_eq!(
            whole.distance_f64(p).to_bits(),
            cells.distance_f64(p).to_bits(),
            "{p}"
        );
        if p.cmpge(lo).all() && p.cmple(hi).all() {
            // In the cell: the subset's fold is the whole fold, bit for bit.
            inside += 1;
            assert_eq!(w.to_bits(), c.to_bits(), "{p}: cells {c}, whole {w}");
        } else {
            // Outside the box: a positive bound of the distance.
            assert!(c > 0.0 && w > 0.0, "{p}: cells {c}, whole {w}");
        }
    }
    assert!(inside > 0);
    // Eight lanes agree with single queries.
    let pts: Vec<Vec3> = probes(8).iter().map(|p| p.as_vec3()).collect();
    for chunk in pts.chunks_exact(8) {
        let p: [Vec3; 8] = std::array::from_fn(|i| chunk[i]);
        let lanes = cells.distance_x8(p);
        for i in 0..8 {
            assert_eq!(lanes[i].to_bits(), cells.distance(p[i]).to_bits());
        }
    }
    // The octree with its budget holds more cells than the lone root.
    let mut octree = compile(&mol);
    let full = octree.build_cells(6, 0.0).expect("bounded");
    assert!(full.program_cells + full.far_cells > 1, "{full:?}");
}

#[test]
fn an_octree_cut_short_by_its_budget_falls_back_to_one_cell_when_asked() {
    // 300 blended spheres: a few thousand units of work cannot refine the crowded octree.
    let mol = molecule(300, 5, 0.026);
    let mut cut = compile(&mol);
    let stats = cut
        .build_cells_within(6, 0.0, 1 << 12, false)
        .expect("bounded");
    assert!(stats.budget_cut, "{stats:?}");
    let mut fallen = compile(&mol);
    let stats = fallen
        .build_cells_within(6, 0.0, 1 << 12, true)
        .expect("bounded");
    assert_eq!((stats.program_cells, stats.far_cells), (1, 0), "{stats:?}");
    // The full budget refines it further.
    let mut full = compile(&mol);
    let refined = full.build_cells(6, 0.0).expect("bounded");
    let cut_cells = cut
        .build_cells_within(6, 0.0, 1 << 12, false)
        .expect("bounded");
    assert!(
        refined.program_cells + refined.far_cells > cut_cells.program_cells + cut_cells.far_cells,
        "{refined:?} vs {cut_cells:?}"
    );
    // Twenty blended spheres apart on a ring finish their octree within a small budget:
    // kept.
    let ring = node(
        NodeKind::Smooth {
            op: SmoothOp::Union,
            children: (0..20)
                .map(|i| {
                    let a = f64::from(i) * std::f64::consts::TAU / 20.0;
                    sphere(0.03, DVec3::new(0.4 * a.cos(), 0.4 * a.sin(), 0.0))
                })
                .collect(),
            blend_radius: 0.02,
        },
        DVec3::ZERO,
    );
    let mut small = compile(&ring);
    let stats = small
        .build_cells_within(6, 0.0, 1 << 18, true)
        .expect("bounded");
    assert!(
        !stats.budget_cut && stats.program_cells + stats.far_cells > 1,
        "{stats:?}"
    );
}

/// An 8-lane query whose lanes lie in several subset cells folds the union of their kept
/// children once when it is shorter than their lists together: the subset lanes take that
/// fold's bits, and every lane what one query gives. On octrees that small budgets cut short
/// (coarse cells that split a bundle, the case the merged fold is for) and the whole octree.
#[test]
fn eight_lanes_over_several_cells_fold_the_union_of_their_children() {
    eight_lanes_over_several_cells_read_the_union_of_their_children(molecule(400, 13, 0.026));
}

#[test]
fn eight_lanes_over_several_cells_blend_the_union_of_their_children() {
    eight_lanes_over_several_cells_read_the_union_of_their_children(blend_molecule(400, 13, 0.026));
}

fn eight_lanes_over_several_cells_read_the_union_of_their_children(mut mol: Node) {
    use marchmesh_field::V3;
    use marchmesh_field::lane::F32x8;
    use marchmesh_field::prune::{Cell, Cells, PruneIndex};
    use std::collections::BTreeSet;
    if let NodeKind::Smooth { children, .. } = &mut mol.kind {
        for (i, c) in children.iter_mut().enumerate() {
            c.material = (i % 3) as u32;
        }
    }
    let whole = whole_program(&mol);
    let p32 = whole.cast::<f32>();
    let spheres = whole.sphere_table::<f32>();
    let (lo, hi) = compile(&mol).bounds().expect("bounded");
    let index = PruneIndex::build(&whole);
    let mut rng = 3u64;
    let mut next = move || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut merged = 0usize;
    for budget in [
        1 << 12,
        1 << 14,
        1 << 16,
        Cells::max_work(whole.instrs.len()),
    ] {
        let mut cells = Cells::build_within(&whole, &index, &[], (lo, hi), 0.01, 6, 0.0, budget)
            .expect("built");
        // A blend's lists per finest cell (nothing for a fold).
        cells.list_blend_children(&whole);
        assert!(cells.stats().subset_cells > 1, "{:?}", cells.stats());
        for _ in 0..600 {
            // Bundles near the walk (within 0.35 of the origin), spread across cells.
            let centre = [next(), next(), next()].map(|v| (2.0 * v - 1.0) * 0.4);
            let gap = [0.01f32, 0.05, 0.15][(next() * 3.0) as usize % 3];
            let lanes: [[f32; 3]; 8] =
                std::array::from_fn(|_| centre.map(|v| v + (2.0 * next() - 1.0) * gap));
            let v8 = V3::new(
                F32x8(lanes.map(|l| l[0])),
                F32x8(lanes.map(|l| l[1])),
                F32x8(lanes.map(|l| l[2])),
            );
            // Eight lanes against one query per lane, value and material.
            let (d, m) = cells.eval_x8::<true>(v8, &p32, &[]);
            let d_only = cells.eval_x8::<false>(v8, &p32, &[]).0;
            for (i, l) in lanes.iter().enumerate() {
                let one = cells.eval::<true>(Vec3::from_array(*l), &p32, &[]);
                assert_eq!((d.0[i].to_bits(), m[i]), (one.0.to_bits(), one.1), "{l:?}");
                let one = cells.eval::<false>(Vec3::from_array(*l), &p32, &[]);
                assert_eq!(d_only.0[i].to_bits(), one.0.to_bits(), "{l:?}");
            }
            // The lanes' distinct subset cells: when the union of their lists is shorter
            // than the lists, the subset lanes hold the fold over that union.
            let mut lists: Vec<&[u32]> = Vec::new();
            for l in &lanes {
                if let Some(Cell::Subset { kids, .. }) = cells.locate(*l)
                    && !lists.iter().any(|k| std::ptr::eq(*k, &**kids))
                {
                    lists.push(kids);
                }
            }
            let union: Vec<u32> = lists
                .iter()
                .flat_map(|k| k.iter().copied())
                .collect::<BTreeSet<_>>()
                .into_iter()
                .collect();
            if lists.len() < 2 || union.len() >= lists.iter().map(|k| k.len()).sum::<usize>() {
                continue;
            }
            merged += 1;
            let b = p32.eval_root_subset::<F32x8, true>(&union, &spheres, &[], v8, &[]);
            for (i, l) in lanes.iter().enumerate() {
                if matches!(cells.locate(*l), Some(Cell::Subset { .. })) {
                    assert_eq!(
                        (d.0[i].to_bits(), m[i]),
                        (b.0.0[i].to_bits(), b.1[i]),
                        "{l:?}"
                    );
                }
            }
        }
    }
    assert!(merged > 100, "{merged} merged queries");
}
