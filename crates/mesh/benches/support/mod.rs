//! Shared setup of the BVH benchmark and the interleaved ratio example: cases, rays, the
//! raw obvhs baseline and the traced loops.
#![allow(dead_code)]

use std::path::Path;
use std::time::Duration;

use glam::{DVec3, Vec3, Vec3A};
use marchmesh_core::{Geometry, Ray};
use marchmesh_mesh::tessellate::{Detail, tessellate};
use marchmesh_mesh::{BvhKind, MeshOptions};
use marchmesh_scene::{NodeKind, Scene, Shape};
use obvhs::{
    BvhBuildParams,
    bvh2::{Bvh2, builder::build_bvh2_from_tris},
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris},
    ray::{Ray as ObRay, RayHit},
    rt_triangle::RtTriangle,
    triangle::Triangle,
};
use rayon::prelude::*;

/// Image side: 500 x 500 primary rays.
pub const SIDE: u32 = 500;
pub const SPHERE_LEVEL: u32 = 7; // 1024 x 512 segments: 1,046,528 triangles

pub struct Case {
    pub name: &'static str,
    pub scene: Scene,
    pub options: MeshOptions,
    /// The triangles in render space, as the backend holds them.
    pub tris: Vec<Triangle>,
}

pub fn scenes_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes")
}

pub fn camera_json(lo: DVec3, hi: DVec3) -> String {
    let c = (lo + hi) * 0.5;
    let r = (hi - lo).length() * 0.5;
    let eye = c + DVec3::new(0.35, 0.45, -2.4) * r;
    format!(
        r#""camera": {{"position": [{}, {}, {}], "look_at": [{}, {}, {}], "vfov_deg": 40, "width": {SIDE}, "height": {SIDE}}}"#,
        eye.x, eye.y, eye.z, c.x, c.y, c.z
    )
}

pub fn mesh_case(name: &'static str, file: &str) -> Case {
    let path = scenes_dir().join("meshes").join(file);
    let mesh = marchmesh_meshio::load_mesh(&path).expect("mesh loads");
    let (lo, hi) = mesh.bounds();
    let json = format!(
        r#"{{{}, "objects": [{{"shape": {{"mesh": {{"path": "meshes/{file}"}}}}}}]}}"#,
        camera_json(lo.as_dvec3(), hi.as_dvec3())
    );
    let scene = marchmesh_scene::parse_scene(&json, name, &scenes_dir()).expect("scene");
    let cam = scene.camera.position;
    let p = |i: u32| Vec3A::from((mesh.positions[i as usize].as_dvec3() - cam).as_vec3());
    let tris = mesh
        .triangles
        .iter()
        .map(|t| Triangle {
            v0: p(t[0]),
            v1: p(t[1]),
            v2: p(t[2]),
        })
        .collect();
    Case {
        name,
        scene,
        options: MeshOptions::default(),
        tris,
    }
}

pub fn sphere_case() -> Case {
    let json = format!(
        r#"{{{}, "objects": [{{"shape": {{"sphere": {{"radius": 1}}}}}}]}}"#,
        camera_json(DVec3::splat(-1.0), DVec3::splat(1.0))
    );
    let scene = marchmesh_scene::parse_scene(&json, "sphere_1m", &scenes_dir()).expect("scene");
    let local = tessellate(
        &NodeKind::Leaf(Shape::Sphere { radius: 1.0 }),
        Detail::Level(SPHERE_LEVEL),
        1 << 16,
    )
    .expect("sphere");
    let cam = scene.camera.position;
    let p = |i: u32| Vec3A::from((local.positions[i as usize] - cam).as_vec3());
    let tris = local
        .triangles
        .iter()
        .map(|t| Triangle {
            v0: p(t[0]),
            v1: p(t[1]),
            v2: p(t[2]),
        })
        .collect();
    Case {
        name: "sphere_1m",
        scene,
        options: MeshOptions {
            tess_level: Some(SPHERE_LEVEL),
            ..MeshOptions::default()
        },
        tris,
    }
}

pub fn primary_rays(scene: &Scene) -> Vec<Ray> {
    let cam = &scene.camera;
    let mut rays = Vec::with_capacity((SIDE * SIDE) as usize);
    for j in 0..cam.height {
        for i in 0..cam.width {
            rays.push(Ray {
                origin: Vec3::ZERO,
                dir: cam
                    .direction(f64::from(i) + 0.5, f64::from(j) + 0.5)
                    .as_vec3(),
                t_min: 0.0,
                t_max: f32::INFINITY,
            });
        }
    }
    rays
}

/// Shadow rays towards a directional light from every primary hit.
pub fn shadow_rays(g: &dyn Geometry, primary: &[Ray], scale: f32) -> Vec<Ray> {
    let light = Vec3::new(1.0, 2.0, -1.0).normalize();
    primary
        .iter()
        .filter_map(|r| g.closest_hit(r).hit().map(|h| (r, h)))
        .map(|(r, h)| {
            let n = if h.normal.dot(r.dir) > 0.0 {
                -h.normal
            } else {
                h.normal
            };
            Ray {
                origin: h.position + n * (1e-4 * scale),
                dir: light,
                t_min: 0.0,
                t_max: f32::INFINITY,
            }
        })
        .collect()
}

pub enum Raw {
    Bvh2(Bvh2, Vec<RtTriangle>),
    CwBvh(CwBvh, Vec<RtTriangle>),
}

pub fn raw_build(kind: BvhKind, tris: &[Triangle]) -> Raw {
    let params = BvhBuildParams::medium_build();
    let mut t = Duration::default();
    match kind {
        // The wide layout is converted from a Bvh2: raw obvhs Bvh2 is its baseline.
        BvhKind::Bvh2 | BvhKind::Wide => {
            let b = build_bvh2_from_tris(tris, params, &mut t);
            let rt = b
                .primitive_indices
                .iter()
                .map(|&i| RtTriangle::from(&tris[i as usize]))
                .collect();
            Raw::Bvh2(b, rt)
        }
        BvhKind::CwBvh => {
            let b = build_cwbvh_from_tris(tris, params, &mut t);
            let rt = b
                .primitive_indices
                .iter()
                .map(|&i| RtTriangle::from(&tris[i as usize]))
                .collect();
            Raw::CwBvh(b, rt)
        }
    }
}

pub fn ob(r: &Ray) -> ObRay {
    ObRay::new(Vec3A::from(r.origin), Vec3A::from(r.dir), r.t_min, r.t_max)
}

/// Raw obvhs: closest hit t (INFINITY for a miss).
pub fn raw_closest(raw: &Raw, r: &Ray) -> f32 {
    let mut hit = RayHit::none();
    match raw {
        Raw::Bvh2(b, t) => {
            b.ray_traverse(ob(r), &mut hit, |ray, id| t[id].intersect(ray));
        }
        Raw::CwBvh(b, t) => {
            b.ray_traverse(ob(r), &mut hit, |ray, id| t[id].intersect(ray));
        }
    }
    hit.t
}

pub fn raw_occluded(raw: &Raw, r: &Ray) -> bool {
    match raw {
        Raw::Bvh2(b, t) => !b.ray_traverse_miss(ob(r), |ray, id| t[id].intersect(ray)),
        Raw::CwBvh(b, t) => !b.ray_traverse_miss(ob(r), |ray, id| t[id].intersect(ray)),
    }
}

pub const CHUNK: usize = 500;

pub fn trace_backend(g: &dyn Geometry, primary: &[Ray], shadow: &[Ray]) -> f64 {
    let a: f64 = primary
        .par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| {
            c.iter()
                .filter_map(|r| g.closest_hit(r).hit().map(|h| f64::from(h.t)))
                .sum::<f64>()
        })
        .sum();
    let b: usize = shadow
        .par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| c.iter().filter(|r| g.occluded(r).occluded).count())
        .sum();
    a + b as f64
}

pub fn trace_raw(raw: &Raw, primary: &[Ray], shadow: &[Ray]) -> f64 {
    let a: f64 = primary
        .par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| {
            c.iter()
                .map(|r| raw_closest(raw, r))
                .filter(|t| t.is_finite())
                .map(f64::from)
                .sum::<f64>()
        })
        .sum();
    let b: usize = shadow
        .par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| c.iter().filter(|r| raw_occluded(raw, r)).count())
        .sum();
    a + b as f64
}
