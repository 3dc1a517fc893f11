//! Test support shared by the workspace's integration tests (a dev-dependency only): the
//! repository's folders, scenes parsed from JSON, renders, camera rays, unique temporary
//! folders, and brute-force f64 oracles (triangle and sphere intersection) to check fast
//! intersection code against.
//!
//! Everything panics with a message on failure: these helpers serve tests, where a panic is
//! the failure report.

pub mod tools;

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use marchmesh_core::{BackgroundSampler, Geometry, Ray, RenderOptions, RenderOutput, render};
use marchmesh_scene::Scene;

/// The repository's root folder.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The repository's `scenes/` folder.
pub fn scenes_dir() -> PathBuf {
    repo_root().join("scenes")
}

/// A fresh, empty folder `marchmesh-<name>-<process id>` in the system's temporary folder
/// (removed first if a crashed earlier run left it). Tests remove it when they pass.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("marchmesh-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
    d
}

/// Parses a scene given as JSON (mesh paths relative to `scenes/`).
pub fn scene(json: &str) -> Scene {
    marchmesh_scene::parse_scene(json, "test", &scenes_dir()).expect("valid test scene")
}

/// Renders `scene` with `geometry` on `threads` threads (0 = all cores).
pub fn render_with(scene: &Scene, geometry: &dyn Geometry, threads: usize) -> RenderOutput {
    let bg = BackgroundSampler::load(&scene.background).expect("background");
    let opts = RenderOptions {
        threads,
        ..Default::default()
    };
    render(scene, geometry, &bg, &opts, &|| {}).expect("render")
}

/// Renders `scene` with `geometry` on one thread (deterministic counters).
pub fn render_1t(scene: &Scene, geometry: &dyn Geometry) -> RenderOutput {
    render_with(scene, geometry, 1)
}

/// Primary rays (render space) through an `n x n` grid of pixel centres of the scene camera.
pub fn camera_rays(scene: &Scene, n: u32) -> Vec<Ray> {
    let cam = &scene.camera;
    let mut rays = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let px = (f64::from(i) + 0.5) / f64::from(n) * f64::from(cam.width);
            let py = (f64::from(j) + 0.5) / f64::from(n) * f64::from(cam.height);
            rays.push(Ray {
                origin: Vec3::ZERO,
                dir: cam.direction(px, py).as_vec3(),
                t_min: 0.0,
                t_max: f32::INFINITY,
            });
        }
    }
    rays
}

/// Closest f64 Möller–Trumbore hit over all triangles (no acceleration structure).
pub fn brute_force_hit(
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    origin: DVec3,
    dir: DVec3,
) -> Option<f64> {
    let mut best: Option<f64> = None;
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let e1 = b - a;
        let e2 = c - a;
        let p = dir.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-300 {
            continue;
        }
        let inv = 1.0 / det;
        let s = origin - a;
        let u = s.dot(p) * inv;
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = s.cross(e1);
        let v = dir.dot(q) * inv;
        if v < 0.0 || u + v > 1.0 {
            continue;
        }
        let t = e2.dot(q) * inv;
        if t > 0.0 && best.is_none_or(|b| t < b) {
            best = Some(t);
        }
    }
    best
}

/// Exact ray-sphere entry distance (f64), if any.
pub fn ray_sphere(origin: DVec3, dir: DVec3, centre: DVec3, radius: f64) -> Option<f64> {
    let oc = origin - centre;
    let b = oc.dot(dir);
    let c = oc.length_squared() - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 0.0).then_some(t)
}

/// Runs the program `bin` (e.g. `env!("CARGO_BIN_EXE_marchmesh")`, which only the binary's own
/// tests can name) with `args` in `cwd`: (exited successfully, stdout, stderr).
pub fn run_program(bin: &str, args: &[&str], cwd: &Path) -> (bool, String, String) {
    let out = std::process::Command::new(bin)
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap_or_else(|e| panic!("running {bin}: {e}"));
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A scene of `levels` nested smooth unions written left-deep, as modelling tools fold a
/// list of primitives: level `k` blends the tree below it (its first child) with one more
/// sphere of radius 0.06, the spheres on a spiral inside the unit box, blend radius 0.0004
/// (tiny, so the bounds grown per fold stay small), camera 3 units away. `levels + 1`
/// spheres in all; the JSON is `levels` levels deep.
pub fn left_deep_smooth_union(levels: usize) -> String {
    let sphere = |k: usize| {
        let t = k as f64 * 0.002;
        let (s, c) = (t * 40.0).sin_cos();
        format!(
            r#"{{"shape": {{"sphere": {{"radius": 0.06}}}}, "transform": {{"translate": [{:.5}, {:.5}, {:.5}]}}}}"#,
            0.7 * c * (1.0 - t / 30.0),
            (t / 10.0).min(1.0) - 0.5,
            0.7 * s * (1.0 - t / 30.0),
        )
    };
    let mut json = String::from(
        r#"{"camera": {"position": [0, 1, -3], "look_at": [0, 0, 0], "vfov_deg": 45}, "objects": ["#,
    );
    for _ in 0..levels {
        json.push_str(r#"{"shape": {"smooth_union": {"blend_radius": 0.0004, "children": ["#);
    }
    json.push_str(&sphere(0));
    for k in 1..=levels {
        json.push_str(", ");
        json.push_str(&sphere(k));
        json.push_str("]}}}");
    }
    json.push_str("]}");
    json
}

/// A unit sphere at the world origin seen from `distance` units, along -z or (`off_axis`)
/// along the (1, 1, -1) diagonal, with a field of view 3.2 units tall at the sphere: the
/// scenes of the stability study's `distance` families, 64 pixels square.
pub fn far_sphere_scene(distance: f64, off_axis: bool) -> Scene {
    let vfov = 2.0 * (1.6f64 / distance).atan().to_degrees();
    let c = distance / 3f64.sqrt();
    let position = if off_axis {
        [c, c, -c]
    } else {
        [0.0, 0.0, -distance]
    };
    scene(&format!(
        r#"{{"camera": {{"position": [{}, {}, {}], "look_at": [0, 0, 0], "vfov_deg": {vfov}, "width": 64, "height": 64}},
            "objects": [{{"shape": {{"sphere": {{"radius": 1}}}}}}],
            "render": {{"max_distance": {}}}}}"#,
        position[0],
        position[1],
        position[2],
        2.0 * distance + 10.0
    ))
}

/// Checks `geometry`'s closest hits of a 48 x 48 fan of camera rays of `scene` (a
/// [`far_sphere_scene`]) against the unit sphere in f64, along each f32 ray as traced: a ray
/// passing more than `band` inside the silhouette must hit, one passing more than `band`
/// outside must miss, and where the ray passes within 0.9 of the centre the hit distance
/// must be within `band` (plus 4 f32 ulps) of the truth and the normal within
/// `max_normal_deg` degrees. Returns the number of hits checked; panics naming the first
/// disagreement.
pub fn check_far_sphere(
    scene: &Scene,
    geometry: &dyn Geometry,
    band: f64,
    max_normal_deg: f64,
) -> usize {
    let centre = -scene.camera.position;
    let mut checked = 0;
    for ray in camera_rays(scene, 48) {
        // The f32 direction is unit only to 2^-24, which over 1e7 units is half a unit: the
        // geometry along the unit direction, the ray parameter along the direction as given.
        let dir = ray.dir.as_dvec3();
        let len = dir.length();
        let unit = dir / len;
        let tc = centre.dot(unit);
        let off = unit * tc - centre;
        let q = off.length();
        let r = geometry.closest_hit(&ray);
        if q > 1.0 + band {
            assert!(
                r.hit().is_none(),
                "ray {dir} passing {q} from the centre hit"
            );
            continue;
        }
        if q >= 1.0 - band {
            continue;
        }
        let Some(h) = r.hit() else {
            panic!("ray {dir} passing {q} from the centre missed: {r:?}");
        };
        if q < 0.9 {
            let t_unit = tc - (1.0 - q * q).sqrt();
            let t = t_unit / len;
            let slack = band + 4.0 * f64::from(f32::EPSILON) * t;
            assert!(
                (f64::from(h.t) - t).abs() <= slack,
                "ray {dir}: t {} vs {t}",
                h.t
            );
            let n = (unit * t_unit - centre).normalize();
            let angle = n
                .dot(h.normal.as_dvec3().normalize())
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees();
            assert!(
                angle <= max_normal_deg,
                "ray {dir}: normal off by {angle} degrees"
            );
            checked += 1;
        }
    }
    checked
}
