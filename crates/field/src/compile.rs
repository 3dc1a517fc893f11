//! Scene tree -> flat [`Program`]: transforms folded into per-node affine maps with their
//! Lipschitz scale, bounding boxes in each parent's frame, repetition windows.

use glam::{DAffine3, DMat3, DVec3};
use marchmesh_scene::{Node, NodeKind, Shape};

use crate::FieldError;
use crate::leaf::Leaf;
use crate::program::{Affine, Instr, MAX_WINDOW, Op, Program};
use crate::shapes::TriData;

pub(crate) use marchmesh_scene::bounds::Aabb;
use marchmesh_scene::bounds::{LocalBounds, combine, singular_values};

/// A leaf shape's box in its own frame, from the scene's one definition of shape bounds.
fn leaf_box(shape: &Shape) -> Aabb {
    match shape.local_bounds() {
        LocalBounds::Finite(b) => b,
        LocalBounds::Unbounded | LocalBounds::MeshFile(_) | LocalBounds::Composite => {
            Aabb::INFINITE
        }
    }
}

/// A mesh the compiler needs a grid for; the caller resolves it.
pub(crate) trait MeshResolver {
    /// Grid index and the mesh's solid bounds in its local frame.
    fn resolve(&mut self, node: &Node) -> Result<(u32, Aabb), FieldError>;
}

pub(crate) struct Compiler<'a> {
    pub instrs: Vec<Instr<f64>>,
    pub notes: Vec<String>,
    pub meshes: &'a mut dyn MeshResolver,
}

fn a3(v: DVec3) -> [f64; 3] {
    v.to_array()
}

impl Compiler<'_> {
    /// Compiles `n` with `xf` = node frame -> program parent frame. Returns its box in the
    /// parent frame.
    pub fn node(&mut self, n: &Node, xf: DAffine3) -> Result<Aabb, FieldError> {
        let inv = xf.inverse();
        let dscale = singular_values(&xf.matrix3)[0];
        if !inv.is_finite()
            || dscale.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            || !dscale.is_finite()
        {
            return Err(FieldError::Degenerate {
                json_path: n.json_path.clone(),
                reason: "transform is singular or not finite".into(),
            });
        }
        if (dscale - 1.0).abs() > 1e-9 {
            let m = xf.matrix3;
            let big = m
                .x_axis
                .length()
                .max(m.y_axis.length())
                .max(m.z_axis.length());
            if big - dscale > 1e-9 * big {
                self.notes.push(format!(
                    "{}: non-uniform scale, distances multiplied by the smallest singular value {dscale:.4} (a bound)",
                    n.json_path
                ));
            }
        }
        let idx = self.instrs.len();
        let lin = if inv.matrix3 == DMat3::IDENTITY {
            None
        } else {
            let m = inv.matrix3.transpose(); // rows of inv = columns of its transpose
            Some([
                m.x_axis.x, m.x_axis.y, m.x_axis.z, m.y_axis.x, m.y_axis.y, m.y_axis.z, m.z_axis.x,
                m.z_axis.y, m.z_axis.z,
            ])
        };
        self.instrs.push(Instr {
            end: 0,
            material: n.material,
            has_bound: false,
            lo: [0.0; 3],
            hi: [0.0; 3],
            tau: 0.0,
            to_local: Affine {
                lin,
                trans: a3(inv.translation),
            },
            dscale,
            op: Op::Union,
        });
        let (op, local) = match &n.kind {
            NodeKind::Leaf(shape) => {
                let (leaf, local) = match shape {
                    Shape::Sphere { radius } => {
                        let m = xf.matrix3;
                        let sc = m.x_axis.length();
                        let g = m.transpose() * m;
                        let conformal = (0..3).all(|c| {
                            (0..3).all(|r| {
                                let want = if c == r { sc * sc } else { 0.0 };
                                (g.col(c)[r] - want).abs() <= 1e-12 * sc * sc
                            })
                        });
                        let c = xf.translation;
                        let r = radius * sc;
                        // Only when the frame origin (the camera, in render space) is close to the
                        // surface relative to the radius does `|p - c| - r` lose precision in f32.
                        if conformal && r >= 16.0 * (c.length() - r).abs() {
                            // Rotation and uniform scale: a sphere in the parent frame, evaluated
                            // without moving the point into the local frame first (see Leaf::SphereAt).
                            self.instrs[idx].evaluate_in_parent_frame();
                            (
                                Leaf::SphereAt {
                                    c: a3(c),
                                    r,
                                    k: (c.length_squared() - r * r),
                                },
                                leaf_box(shape),
                            )
                        } else {
                            (Leaf::Sphere { r: *radius }, leaf_box(shape))
                        }
                    }
                    Shape::Plane { normal, offset } => {
                        // A plane stays a plane under any affine map: express it in the parent frame
                        // in f64 (`n.(A x + b) = offset`) and evaluate it there, exactly. Moving the
                        // point into the local frame in f32 instead would add the camera's world
                        // position back (1e5 units away: 0.008-unit rounding, step exhaustion).
                        let a = inv.matrix3;
                        let n_parent = a.transpose() * *normal;
                        let len = n_parent.length();
                        let offset_parent = (offset - normal.dot(inv.translation)) / len;
                        self.instrs[idx].evaluate_in_parent_frame();
                        (
                            Leaf::Plane {
                                n: a3(n_parent / len),
                                offset: offset_parent,
                            },
                            Aabb::INFINITE,
                        )
                    }
                    Shape::Box { half_extents } => (
                        Leaf::Box {
                            b: a3(*half_extents),
                        },
                        leaf_box(shape),
                    ),
                    Shape::Ellipsoid { radii } => (
                        Leaf::Ellipsoid {
                            inv_r: a3(radii.recip()),
                            rmin: radii.min_element(),
                        },
                        leaf_box(shape),
                    ),
                    Shape::Cylinder {
                        radius,
                        half_height,
                    } => (
                        Leaf::Cylinder {
                            r: *radius,
                            h: *half_height,
                        },
                        leaf_box(shape),
                    ),
                    Shape::Torus {
                        major_radius,
                        minor_radius,
                    } => (
                        Leaf::Torus {
                            big: *major_radius,
                            small: *minor_radius,
                        },
                        leaf_box(shape),
                    ),
                    Shape::RoundedBox {
                        half_extents,
                        rounding_radius,
                    } => (
                        Leaf::RoundedBox {
                            b: a3((*half_extents - DVec3::splat(*rounding_radius)).max(DVec3::ZERO)),
                            r: *rounding_radius,
                        },
                        leaf_box(shape),
                    ),
                    Shape::Capsule {
                        radius,
                        half_height,
                    } => (
                        Leaf::Capsule {
                            h: *half_height,
                            r: *radius,
                        },
                        leaf_box(shape),
                    ),
                    Shape::CappedCone {
                        half_height,
                        bottom_radius,
                        top_radius,
                    } => {
                        let k2 =
                            (top_radius - bottom_radius).powi(2) + 4.0 * half_height * half_height;
                        (
                            Leaf::CappedCone {
                                h: *half_height,
                                r1: *bottom_radius,
                                r2: *top_radius,
                                inv_k2: 1.0 / k2,
                            },
                            leaf_box(shape),
                        )
                    }
                    Shape::Triangle { vertices } => {
                        let [a, b, c] = *vertices;
                        let (ba, cb, ac) = (b - a, c - b, a - c);
                        let nor = ba.cross(ac);
                        if nor.length_squared().partial_cmp(&0.0)
                            != Some(std::cmp::Ordering::Greater)
                        {
                            return Err(FieldError::Degenerate {
                                json_path: n.json_path.clone(),
                                reason: "triangle has collinear vertices".into(),
                            });
                        }
                        let t = TriData {
                            a: a3(a),
                            b: a3(b),
                            c: a3(c),
                            ba: a3(ba),
                            cb: a3(cb),
                            ac: a3(ac),
                            en: [a3(ba.cross(nor)), a3(cb.cross(nor)), a3(ac.cross(nor))],
                            n: a3(nor.normalize()),
                            inv2: [
                                1.0 / ba.length_squared(),
                                1.0 / cb.length_squared(),
                                1.0 / ac.length_squared(),
                            ],
                        };
                        (Leaf::Triangle(Box::new(t)), leaf_box(shape))
                    }
                    Shape::Mesh { .. } => {
                        let (grid, bb) = self.meshes.resolve(n)?;
                        (Leaf::Mesh { grid }, bb)
                    }
                };
                (Op::Leaf(leaf), local)
            }
            NodeKind::Union(ch) if ch.len() > GROUP => {
                let items: Vec<(&Node, DAffine3)> = ch.iter().map(|c| (c, c.transform)).collect();
                (Op::Union, self.grouped_union(&items)?)
            }
            NodeKind::Union(ch) | NodeKind::Intersection(ch) | NodeKind::Subtraction(ch) => {
                let boxes = self.children(ch)?;
                let op = match &n.kind {
                    NodeKind::Union(_) => Op::Union,
                    NodeKind::Intersection(_) => Op::Intersection,
                    _ => Op::Subtraction,
                };
                (op, combine(&n.kind, &boxes).unwrap_or(Aabb::INFINITE))
            }
            NodeKind::Smooth {
                op,
                children,
                blend_radius,
            } => {
                let boxes = self.children(children)?;
                (
                    Op::Smooth {
                        op: *op,
                        k: *blend_radius,
                        inv_k: 1.0 / blend_radius,
                    },
                    combine(&n.kind, &boxes).unwrap_or(Aabb::INFINITE),
                )
            }
            NodeKind::Repeat {
                child,
                period,
                count,
            } => {
                let cb = self.node(child, child.transform)?;
                let bb = combine(&n.kind, &[cb]).unwrap_or(Aabb::INFINITE);
                let mut cnt = [0.0; 3];
                let mut first = [0.0; 3];
                let mut r = f64::INFINITY;
                for a in 0..3 {
                    if period[a] > 0.0 {
                        r = r.min(period[a] * 0.5);
                    }
                }
                let mut exact = true;
                for a in 0..3 {
                    let p = period[a];
                    if p <= 0.0 {
                        continue;
                    }
                    let w = cb.hi[a] - cb.lo[a];
                    let rmax = ((MAX_WINDOW - 1) as f64 * p - w) * 0.5;
                    if w.is_finite() && rmax > 1e-3 * p {
                        r = r.min(rmax);
                    } else {
                        exact = false;
                    }
                    if let Some(c) = count[a] {
                        cnt[a] = c as f64;
                        first[a] = -(c as f64 - 1.0) * 0.5 * p;
                    }
                }
                if !r.is_finite() {
                    r = 1e30;
                }
                if !exact {
                    self.notes.push(format!(
                        "{}: repeated child is wider than {} periods (or unbounded) along a repeated axis; only the nearest {} copies per axis are evaluated and the distance may over-estimate",
                        n.json_path,
                        MAX_WINDOW - 1,
                        MAX_WINDOW
                    ));
                }
                (
                    Op::Repeat {
                        period: a3(*period),
                        count: cnt,
                        first,
                        r,
                    },
                    bb,
                )
            }
        };
        let parent_box = local.transformed(&xf);
        let cheap = matches!(
            op,
            Op::Leaf(
                Leaf::Sphere { .. } | Leaf::SphereAt { .. } | Leaf::Box { .. } | Leaf::Plane { .. }
            )
        );
        let end = self.instrs.len() as u32;
        let ins = &mut self.instrs[idx];
        ins.op = op;
        ins.end = end;
        ins.lo = a3(parent_box.lo);
        ins.hi = a3(parent_box.hi);
        ins.has_bound = !cheap && parent_box.any_finite();
        let leaf = matches!(ins.op, Op::Leaf(_));
        // Leaves keep only the exact skips (their value is >= the box distance anyway), so
        // exact primitives stay exact everywhere; subtrees switch to their box beyond tau.
        ins.tau = if leaf && !matches!(ins.op, Op::Leaf(Leaf::Mesh { .. })) {
            f64::INFINITY
        } else if parent_box.is_finite() {
            ((parent_box.hi - parent_box.lo).length() * 0.5).max(1e-30)
        } else {
            f64::INFINITY
        };
        Ok(parent_box)
    }

    fn children(&mut self, ch: &[Node]) -> Result<Vec<Aabb>, FieldError> {
        ch.iter().map(|c| self.node(c, c.transform)).collect()
    }

    /// Emits the children of a union with many members under a hierarchy of synthetic
    /// identity unions (median splits of the box centres, at most [`GROUP`] members each),
    /// so a point far from a group pays one box test for it. Union is associative and the
    /// synthetic nodes use only the exact skip (infinite tau): values are unchanged.
    /// Members with unbounded boxes (planes, infinite repetition) stay at the top. Returns
    /// the hull of all members.
    fn grouped_union(&mut self, items: &[(&Node, DAffine3)]) -> Result<Aabb, FieldError> {
        let mut compiled: Vec<(Vec<Instr<f64>>, Aabb)> = Vec::with_capacity(items.len());
        for (n, xf) in items {
            let mut sub = Compiler {
                instrs: Vec::new(),
                notes: Vec::new(),
                meshes: &mut *self.meshes,
            };
            let b = sub.node(n, *xf)?;
            self.notes.append(&mut sub.notes);
            compiled.push((sub.instrs, b));
        }
        let hull = compiled
            .iter()
            .skip(1)
            .fold(compiled[0].1, |a, c| a.hull(&c.1));
        let (finite, unbounded): (Vec<_>, Vec<_>) =
            compiled.into_iter().partition(|c| c.1.is_finite());
        for c in unbounded {
            self.splice(c.0);
        }
        self.emit_group(finite);
        Ok(hull)
    }

    fn splice(&mut self, instrs: Vec<Instr<f64>>) {
        let off = self.instrs.len() as u32;
        self.instrs.extend(instrs.into_iter().map(|mut i| {
            i.end += off;
            i
        }));
    }

    fn emit_group(&mut self, mut items: Vec<(Vec<Instr<f64>>, Aabb)>) {
        if items.len() <= GROUP {
            for (instrs, _) in items {
                self.splice(instrs);
            }
            return;
        }
        let hull = items.iter().skip(1).fold(items[0].1, |a, c| a.hull(&c.1));
        let idx = self.instrs.len();
        self.instrs.push(Instr {
            end: 0,
            material: items[0].0[0].material,
            has_bound: true,
            lo: a3(hull.lo),
            hi: a3(hull.hi),
            tau: f64::INFINITY,
            to_local: Affine {
                lin: None,
                trans: [0.0; 3],
            },
            dscale: 1.0,
            op: Op::Union,
        });
        let ext = hull.hi - hull.lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        items.sort_by(|a, b| {
            let ca = a.1.lo[axis] + a.1.hi[axis];
            let cb = b.1.lo[axis] + b.1.hi[axis];
            ca.total_cmp(&cb)
        });
        let right = items.split_off(items.len() / 2);
        self.emit_group(items);
        self.emit_group(right);
        self.instrs[idx].end = self.instrs.len() as u32;
    }
}

/// Most members of one union node before a hierarchy is built over them.
pub const GROUP: usize = 8;

/// Builds the program for `nodes` (each with `xf(node)` as its node->frame transform) under
/// an identity union root; a single node compiles without the root.
pub(crate) type Compiled = (Program<f64>, Option<Aabb>, Vec<String>);

pub(crate) fn compile_roots(
    nodes: &[(&Node, DAffine3)],
    meshes: &mut dyn MeshResolver,
) -> Result<Compiled, FieldError> {
    let mut c = Compiler {
        instrs: Vec::new(),
        notes: Vec::new(),
        meshes,
    };
    let bb = match nodes {
        [] => None,
        [(n, xf)] => Some(c.node(n, *xf)?),
        _ => {
            c.instrs.push(Instr {
                end: 0,
                material: nodes[0].0.material,
                has_bound: false,
                lo: [0.0; 3],
                hi: [0.0; 3],
                tau: f64::INFINITY,
                to_local: Affine {
                    lin: None,
                    trans: [0.0; 3],
                },
                dscale: 1.0,
                op: Op::Union,
            });
            let h = if nodes.len() > GROUP {
                c.grouped_union(nodes)?
            } else {
                let mut hull: Option<Aabb> = None;
                for (n, xf) in nodes {
                    let b = c.node(n, *xf)?;
                    hull = Some(hull.map_or(b, |h| h.hull(&b)));
                }
                hull.expect("at least two roots")
            };
            let end = c.instrs.len() as u32;
            let root = &mut c.instrs[0];
            root.end = end;
            root.lo = a3(h.lo);
            root.hi = a3(h.hi);
            root.has_bound = h.any_finite();
            root.tau = if h.is_finite() {
                ((h.hi - h.lo).length() * 0.5).max(1e-30)
            } else {
                f64::INFINITY
            };
            Some(h)
        }
    };
    Ok((Program { instrs: c.instrs }, bb, c.notes))
}
