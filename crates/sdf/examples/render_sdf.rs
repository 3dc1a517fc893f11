//! Renders a scene with the SDF backend and prints its counters; for scenes made only of
//! spheres (e.g. `seed-spheres`) also the primary-hit normal error against the analytic
//! sphere normals, which is how the default `normal_step` was chosen.
//!
//! `cargo run --release -p marchmesh-sdf --example render_sdf -- scenes/seed-spheres.json
//! [side=128] [normal_step=0.02] [eps=0.25] [relax=1.2] [threads=1] [out.png]`

use std::path::Path;

use marchmesh_core::{BackgroundSampler, Geometry, RenderOptions, RenderSpace, render};
use marchmesh_scene::{NodeKind, Shape};
use marchmesh_sdf::{SdfOptions, build};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        eprintln!(
            "usage: render_sdf SCENE [side=128] [normal_step=0.02] [eps=0.25] [relax=1.2] [threads=1] [out.png]"
        );
        std::process::exit(2);
    };
    let arg = |i: usize, d: f64| -> f64 { args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d) };
    let side = arg(1, 128.0) as u32;
    let opts = SdfOptions {
        normal_step: arg(2, SdfOptions::DEFAULT.normal_step),
        eps_px: arg(3, 0.25),
        relaxation: arg(4, SdfOptions::DEFAULT.relaxation),
        ..SdfOptions::DEFAULT
    };
    let threads = arg(5, 1.0) as usize;
    let scene = match marchmesh_scene::load(Path::new(path)) {
        Ok(s) => s.with_image_size(side, side).unwrap_or_else(|e| {
            eprintln!("{e}");
            std::process::exit(1)
        }),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let g = match build(&scene, &opts) {
        Ok(g) => g,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let bg = BackgroundSampler::load(&scene.background).expect("background");
    let out = render(
        &scene,
        &g,
        &bg,
        &RenderOptions {
            threads,
            ..Default::default()
        },
        &|| {},
    )
    .expect("render");
    let st = &out.stats;
    let rep = g.report();
    println!(
        "{path} {side}x{side}: {:.1} ms, {:.2} Mrays/s, mean steps {:.2}, max steps {}, exhaustion {:.4}% (closest {}, shadow {}), max-distance {}, memory {} B",
        out.elapsed.as_secs_f64() * 1e3,
        st.total_rays() as f64 / out.elapsed.as_secs_f64() / 1e6,
        st.mean_steps(),
        st.max_steps_seen,
        100.0 * st.step_exhaustion_rate(),
        st.closest_max_steps,
        st.occlusion_max_steps,
        st.max_distance,
        rep.memory_bytes
    );
    // Analytic normal error when every object is a sphere.
    let rs = RenderSpace::of(&scene);
    let spheres: Vec<(glam::DVec3, f64)> = scene
        .objects
        .iter()
        .filter_map(|o| match o.kind {
            NodeKind::Leaf(Shape::Sphere { radius }) => {
                let s = o.transform.matrix3.x_axis.length();
                Some((rs.point(o.transform.translation), radius * s))
            }
            _ => None,
        })
        .collect();
    if spheres.len() == scene.objects.len() {
        let fb = &out.framebuffer;
        let mut errs = Vec::new();
        let c = &scene.camera;
        for y in 0..fb.height {
            for x in 0..fb.width {
                let i = (y * fb.width + x) as usize;
                if !fb.depth[i].is_finite() {
                    continue;
                }
                let d = c.direction(x as f64 + 0.5, y as f64 + 0.5).normalize();
                let p = d * fb.depth[i] as f64;
                let (k, (cen, _)) = spheres
                    .iter()
                    .enumerate()
                    .min_by(|a, b| {
                        ((p - a.1.0).length() - a.1.1)
                            .abs()
                            .total_cmp(&((p - b.1.0).length() - b.1.1).abs())
                    })
                    .expect("spheres");
                let mut n = (p - *cen).normalize();
                if n.dot(d) > 0.0 {
                    n = -n;
                }
                let got = fb.normal[i].as_dvec3();
                // |dot|: at grazing incidence the flip towards the camera is ill-conditioned
                // for both normals; a sign flip there says nothing about the field normal.
                let e = got.dot(n).abs().min(1.0).acos().to_degrees();
                if e > 5.0 && std::env::var_os("SDF_DEBUG").is_some() {
                    eprintln!(
                        "pixel {x},{y} sphere {k} err {e:.2} got {got:?} want {n:?} depth {}",
                        fb.depth[i]
                    );
                }
                errs.push(e);
            }
        }
        errs.sort_by(f64::total_cmp);
        if !errs.is_empty() {
            println!(
                "normal error vs analytic (primary ray of sample 0; AA jitter ignored): mean {:.4} deg, p95 {:.4} deg, max {:.4} deg over {} hits",
                errs.iter().sum::<f64>() / errs.len() as f64,
                errs[errs.len() * 95 / 100],
                errs[errs.len() - 1],
                errs.len()
            );
        }
    }
    // OFFSET0=1: render again with render.ray_offset = 0 and count pixels whose colour
    // changes by more than 1/255 (how much the shadow/reflection rays rely on the offset).
    if std::env::var_os("OFFSET0").is_some() {
        let mut s0 = scene.clone();
        s0.render.ray_offset = 0.0;
        let g0 = build(&s0, &opts).expect("builds");
        let o0 = render(
            &s0,
            &g0,
            &bg,
            &RenderOptions {
                threads,
                ..Default::default()
            },
            &|| {},
        )
        .expect("render");
        let changed = out
            .framebuffer
            .color
            .iter()
            .zip(&o0.framebuffer.color)
            .filter(|(a, b)| (**a - **b).abs().max_element() > 1.0 / 255.0)
            .count();
        println!(
            "ray_offset 0 vs scene offset: {changed} of {} pixels change by > 1/255",
            out.framebuffer.color.len()
        );
    }
    if let Some(png) = args.get(6) {
        marchmesh_core::image_io::write_png(&out.framebuffer, Path::new(png)).expect("png");
    }
}
