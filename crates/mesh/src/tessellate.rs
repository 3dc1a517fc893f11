//! Tessellation of the analytic shapes into indexed triangle meshes in the shape's local frame.
//!
//! Curved shapes are surfaces of revolution (sphere, cylinder, torus) or a scaled sphere
//! (ellipsoid) sampled on a uniform parameter grid. The number of segments per direction comes
//! from the chord-error bound of linear interpolation: a curve with `|p''| <= M` per unit
//! parameter, sampled every `h`, deviates from its chords by at most `M h^2 / 8`; each grid
//! direction gets half the budget, so a triangle's error stays within the whole budget.
//! Closed shapes come out watertight (every edge shared by two triangles once vertices at the
//! same position are identified; caps and sides keep separate vertices for their normals),
//! counter-clockwise seen from outside.

use std::f64::consts::TAU;

use glam::DVec3;
use marchmesh_scene::NodeKind;

/// An indexed triangle mesh in a shape's local frame (f64, converted to f32 once placed).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LocalMesh {
    /// Vertex positions, local units.
    pub positions: Vec<DVec3>,
    /// Unit outward vertex normals (same length as `positions`), or `None` for flat faces.
    pub normals: Option<Vec<DVec3>>,
    /// Counter-clockwise (seen from outside) triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Whether the exact surface is closed (the tessellation then is too).
    pub closed: bool,
    /// Segments per full turn used for each curved direction (empty for flat shapes).
    pub segments: Vec<u32>,
    /// Material per triangle (surfaces extracted from CSG); `None`: the placement's.
    pub materials: Option<Vec<marchmesh_scene::MaterialId>>,
}

/// How fine a tessellation must be, in the shape's local frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Detail {
    /// Largest chord error in local units (> 0).
    ChordError(f64),
    /// `8 * 2^level` segments per full turn.
    Level(u32),
}

/// Segments for a direction spanning `fraction` of a full turn whose points move with
/// second derivative at most `curvature_bound` per radian; clamped to
/// `[min, max_per_turn * fraction]`.
pub fn segments(
    detail: Detail,
    curvature_bound: f64,
    fraction: f64,
    min: u32,
    max_per_turn: u32,
) -> u32 {
    let max = ((f64::from(max_per_turn) * fraction).ceil() as u32).max(min);
    let n = match detail {
        Detail::ChordError(e) => {
            if e.is_nan() || e <= 0.0 || curvature_bound.is_nan() || curvature_bound <= 0.0 {
                return max;
            }
            // Half the budget per direction: M h^2 / 8 <= e / 2  =>  h = 2 sqrt(e / M).
            let h = 2.0 * (e / curvature_bound).sqrt();
            let n = (TAU * fraction / h).ceil();
            if n.is_finite() {
                n.min(f64::from(u32::MAX)) as u32
            } else {
                max
            }
        }
        Detail::Level(level) => {
            let per_turn = 8u64 << level.min(24);
            (per_turn as f64 * fraction).round() as u32
        }
    };
    n.clamp(min, max)
}

/// One point of a revolution profile in the (radial, y) half plane.
#[derive(Debug, Clone, Copy)]
struct ProfilePoint {
    radial: f64,
    y: f64,
    /// Outward unit normal (radial, y).
    normal: (f64, f64),
    /// On the axis: one vertex instead of a ring.
    pole: bool,
}

/// Revolves profile polylines about the y axis with `n` segments (counter-clockwise from
/// outside when each polyline runs so that `(-dy, dr)` points outward). A `closed` polyline
/// connects its last point back to its first.
fn revolve(pieces: &[(Vec<ProfilePoint>, bool)], n: u32, mesh: &mut LocalMesh) {
    let n = n.max(3);
    let (sin, cos): (Vec<f64>, Vec<f64>) = (0..n)
        .map(|j| (TAU * f64::from(j) / f64::from(n)).sin_cos())
        .unzip();
    let normals = mesh.normals.get_or_insert_with(Vec::new);
    for (profile, closed) in pieces {
        // First vertex index of each profile row.
        let mut rows: Vec<(u32, bool)> = Vec::with_capacity(profile.len());
        for p in profile {
            let start = mesh.positions.len() as u32;
            if p.pole {
                mesh.positions.push(DVec3::new(0.0, p.y, 0.0));
                normals.push(DVec3::new(0.0, p.normal.1.signum(), 0.0));
            } else {
                for j in 0..n as usize {
                    mesh.positions
                        .push(DVec3::new(p.radial * cos[j], p.y, p.radial * sin[j]));
                    normals.push(DVec3::new(
                        p.normal.0 * cos[j],
                        p.normal.1,
                        p.normal.0 * sin[j],
                    ));
                }
            }
            rows.push((start, p.pole));
        }
        let count = rows.len();
        let bands = if *closed {
            count
        } else {
            count.saturating_sub(1)
        };
        for k in 0..bands {
            let (top, top_pole) = rows[k];
            let (bottom, bottom_pole) = rows[(k + 1) % count];
            let at = |start: u32, pole: bool, j: u32| if pole { start } else { start + j % n };
            for j in 0..n {
                let a = at(top, top_pole, j);
                let b = at(top, top_pole, j + 1);
                let c = at(bottom, bottom_pole, j);
                let d = at(bottom, bottom_pole, j + 1);
                if !top_pole {
                    mesh.triangles.push([a, b, c]);
                }
                if !bottom_pole {
                    mesh.triangles.push([b, d, c]);
                }
            }
        }
    }
}

/// A UV sphere of radius 1 with `n_lon` segments around y and `n_lat` from pole to pole.
fn unit_sphere(n_lon: u32, n_lat: u32) -> LocalMesh {
    let n_lat = n_lat.max(2);
    let profile: Vec<ProfilePoint> = (0..=n_lat)
        .map(|k| {
            let theta = std::f64::consts::PI * f64::from(k) / f64::from(n_lat);
            let (s, c) = theta.sin_cos();
            let pole = k == 0 || k == n_lat;
            ProfilePoint {
                radial: if pole { 0.0 } else { s },
                y: if k == 0 {
                    1.0
                } else if k == n_lat {
                    -1.0
                } else {
                    c
                },
                normal: (
                    if pole { 0.0 } else { s },
                    if k == 0 {
                        1.0
                    } else if k == n_lat {
                        -1.0
                    } else {
                        c
                    },
                ),
                pole,
            }
        })
        .collect();
    let mut mesh = LocalMesh {
        closed: true,
        segments: vec![n_lon.max(3), 2 * n_lat],
        ..LocalMesh::default()
    };
    revolve(&[(profile, false)], n_lon, &mut mesh);
    mesh
}

/// Tessellates an analytic shape (`Sphere`, `Ellipsoid`, `Box`, `Cylinder`, `Torus`,
/// `Triangle`) in its local frame. Returns `None` for shapes without a finite local
/// tessellation (plane, mesh, composites).
pub fn tessellate(kind: &NodeKind, detail: Detail, max_per_turn: u32) -> Option<LocalMesh> {
    let mesh = match *kind {
        NodeKind::Sphere { radius } => {
            let n_lon = segments(detail, radius, 1.0, 3, max_per_turn);
            let n_lat = segments(detail, radius, 0.5, 2, max_per_turn);
            let mut m = unit_sphere(n_lon, n_lat);
            for p in &mut m.positions {
                *p *= radius;
            }
            m
        }
        NodeKind::Ellipsoid { radii } => {
            // Scaled unit sphere: |p_uu|, |p_vv| <= max radius.
            let m_bound = radii.max_element();
            let n_lon = segments(detail, m_bound, 1.0, 3, max_per_turn);
            let n_lat = segments(detail, m_bound, 0.5, 2, max_per_turn);
            let mut m = unit_sphere(n_lon, n_lat);
            for p in &mut m.positions {
                *p *= radii;
            }
            if let Some(normals) = &mut m.normals {
                for n in normals.iter_mut() {
                    *n = (*n / radii).normalize();
                }
            }
            m
        }
        NodeKind::Cylinder {
            radius,
            half_height,
        } => {
            let n = segments(detail, radius, 1.0, 3, max_per_turn);
            let h = half_height;
            let rim = |y: f64, normal: (f64, f64)| ProfilePoint {
                radial: radius,
                y,
                normal,
                pole: false,
            };
            let centre = |y: f64| ProfilePoint {
                radial: 0.0,
                y,
                normal: (0.0, y.signum()),
                pole: true,
            };
            let mut m = LocalMesh {
                closed: true,
                segments: vec![n.max(3)],
                ..LocalMesh::default()
            };
            revolve(
                &[
                    (vec![centre(h), rim(h, (0.0, 1.0))], false),
                    (vec![rim(h, (1.0, 0.0)), rim(-h, (1.0, 0.0))], false),
                    (vec![rim(-h, (0.0, -1.0)), centre(-h)], false),
                ],
                n,
                &mut m,
            );
            m
        }
        NodeKind::Torus {
            major_radius,
            minor_radius,
        } => {
            let n_major = segments(detail, major_radius + minor_radius, 1.0, 3, max_per_turn);
            let n_minor = segments(detail, minor_radius, 1.0, 3, max_per_turn);
            let profile: Vec<ProfilePoint> = (0..n_minor)
                .map(|k| {
                    let (s, c) = (TAU * f64::from(k) / f64::from(n_minor)).sin_cos();
                    ProfilePoint {
                        radial: major_radius + minor_radius * c,
                        y: -minor_radius * s,
                        normal: (c, -s),
                        pole: false,
                    }
                })
                .collect();
            let mut m = LocalMesh {
                closed: true,
                segments: vec![n_major.max(3), n_minor],
                ..LocalMesh::default()
            };
            revolve(&[(profile, true)], n_major, &mut m);
            m
        }
        NodeKind::Box { half_extents } => box_mesh(half_extents),
        NodeKind::Triangle { vertices } => LocalMesh {
            positions: vertices.to_vec(),
            normals: None,
            triangles: vec![[0, 1, 2]],
            closed: false,
            segments: Vec::new(),
            materials: None,
        },
        _ => return None,
    };
    Some(mesh)
}

/// The 12 triangles of an axis-aligned box (exact; flat faces, no vertex normals).
fn box_mesh(half: DVec3) -> LocalMesh {
    let corner =
        |sx: bool, sy: bool, sz: bool| u32::from(sx) | (u32::from(sy) << 1) | (u32::from(sz) << 2);
    let positions = (0..8u32)
        .map(|i| {
            DVec3::new(
                if i & 1 != 0 { half.x } else { -half.x },
                if i & 2 != 0 { half.y } else { -half.y },
                if i & 4 != 0 { half.z } else { -half.z },
            )
        })
        .collect();
    // Each face as (normal axis, sign, u axis, v axis) with u x v = normal.
    let faces = [
        (0, true, 1, 2),
        (0, false, 2, 1),
        (1, true, 2, 0),
        (1, false, 0, 2),
        (2, true, 0, 1),
        (2, false, 1, 0),
    ];
    let mut triangles = Vec::with_capacity(12);
    for (axis, positive, u, v) in faces {
        let at = |su: bool, sv: bool| {
            let mut s = [false; 3];
            s[axis] = positive;
            s[u] = su;
            s[v] = sv;
            corner(s[0], s[1], s[2])
        };
        let (a, b, c, d) = (
            at(false, false),
            at(true, false),
            at(true, true),
            at(false, true),
        );
        triangles.push([a, b, c]);
        triangles.push([a, c, d]);
    }
    LocalMesh {
        positions,
        normals: None,
        triangles,
        closed: true,
        segments: Vec::new(),
        materials: None,
    }
}

/// Exact distance from `p` to the surface of an analytic shape (local frame), for measuring
/// tessellation error; `None` for shapes without one here (ellipsoid, plane, composites).
pub fn exact_surface_distance(kind: &NodeKind, p: DVec3) -> Option<f64> {
    Some(match *kind {
        NodeKind::Sphere { radius } => (p.length() - radius).abs(),
        NodeKind::Box { half_extents } => {
            let q = p.abs() - half_extents;
            (q.max(DVec3::ZERO).length() + q.max_element().min(0.0)).abs()
        }
        NodeKind::Cylinder {
            radius,
            half_height,
        } => {
            let d = glam::DVec2::new(glam::DVec2::new(p.x, p.z).length(), p.y).abs()
                - glam::DVec2::new(radius, half_height);
            (d.x.max(d.y).min(0.0) + d.max(glam::DVec2::ZERO).length()).abs()
        }
        NodeKind::Torus {
            major_radius,
            minor_radius,
        } => {
            let q = glam::DVec2::new(glam::DVec2::new(p.x, p.z).length() - major_radius, p.y);
            (q.length() - minor_radius).abs()
        }
        _ => return None,
    })
}
