//! Hostile input to `render`, `validate` and `view`: environment maps are budgeted from their
//! header before decoding (and `validate` says so), errors print each OS error once, and
//! nonsense view steps are refused up front; `--max-seconds` covers the build as well as the
//! render; a closed stdout never panics `render`, `bench` or `stability`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

mod support;
use support::{marchmesh, stderr, tmp};

/// CRC-32 (IEEE) of `bytes`, as PNG chunks carry it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG whose header declares `width` x `height` RGB pixels and which holds no image data:
/// a few dozen bytes standing for a huge decode.
fn png_declaring(width: u32, height: u32) -> Vec<u8> {
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        png.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend(data);
        png.extend(&body);
        png.extend(crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend(width.to_be_bytes());
    ihdr.extend(height.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    // An empty zlib stream: a decoder reads the header up to the first image data chunk.
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    png
}

fn env_scene(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("env.png"), png_declaring(16384, 16384)).unwrap();
    let p = dir.join("s.json");
    std::fs::write(
        &p,
        r#"{"camera": {"width": 8, "height": 8}, "background": {"environment": {"path": "env.png"}},
            "objects": [{"shape": {"sphere": {}}}]}"#,
    )
    .unwrap();
    p
}

#[test]
fn environment_maps_over_the_memory_limit_are_refused_from_their_header() {
    let dir = tmp("render-env");
    let scene = env_scene(&dir);
    let s = scene.to_str().unwrap();
    let o = marchmesh(&["validate", s], &dir);
    assert!(!o.status.success(), "validate said ok");
    assert!(
        stderr(&o).contains("env.png") && stderr(&o).contains("16384x16384"),
        "{}",
        stderr(&o)
    );
    let o = marchmesh(&["render", s, "--out", "a.png"], &dir);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("16384x16384") && e.contains("memory limit"),
        "{e}"
    );
    assert!(!dir.join("a.png").exists());
}

#[test]
fn os_errors_are_printed_once() {
    let dir = tmp("render-twice");
    for args in [
        vec!["render", "missing.json", "--out", "a.png"],
        vec!["bench", "--suite", "./missing.json", "--list"],
        vec!["report", "missing-run"],
    ] {
        let o = marchmesh(&args, &dir);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert_eq!(
            e.matches("No such file or directory").count(),
            1,
            "{args:?}: {e}"
        );
    }
}

#[test]
fn view_refuses_a_nonsense_step_before_opening_anything() {
    let dir = tmp("render-step");
    let scene = dir.join("s.json");
    std::fs::write(
        &scene,
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"sphere": {}}}]}"#,
    )
    .unwrap();
    let script = dir.join("walk.json");
    std::fs::write(&script, r#"[{"key": "W", "frames": 2}]"#).unwrap();
    for step in ["1e308", "-1", "NaN", "0"] {
        let o = marchmesh(
            &[
                "view",
                scene.to_str().unwrap(),
                "--headless",
                "--script",
                script.to_str().unwrap(),
                "--frames",
                "frames",
                // `--step=-1`: as a separate word, clap would take `-1` for a flag.
                &format!("--step={step}"),
            ],
            &dir,
        );
        assert!(!o.status.success(), "{step}");
        let e = stderr(&o);
        assert!(e.contains("--step") && !e.contains("{ "), "{step}: {e}");
    }
}

#[test]
fn a_closed_stdout_ends_render_bench_and_stability_quietly() {
    let dir = tmp("render-pipe");
    let scene = dir.join("s.json");
    std::fs::write(
        &scene,
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"sphere": {}}}]}"#,
    )
    .unwrap();
    let repo = marchmesh_testkit::repo_root();
    let out = dir.join("runs");
    let st = dir.join("st");
    let cases: Vec<(Vec<&str>, &Path)> = vec![
        (
            vec!["render", scene.to_str().unwrap(), "--out", "a.png"],
            &dir,
        ),
        (
            vec![
                "bench",
                "--suite",
                "smoke",
                "--filter",
                "csg/sdf",
                "--out",
                out.to_str().unwrap(),
            ],
            &repo,
        ),
        (
            vec![
                "stability",
                "--filter",
                "far_origin/offset=",
                "--side",
                "8",
                "--out",
                st.to_str().unwrap(),
            ],
            &repo,
        ),
    ];
    for (args, cwd) in cases {
        let mut child = Command::new(env!("CARGO_BIN_EXE_marchmesh"))
            .args(&args)
            .current_dir(cwd)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let e = stderr(&o);
        assert!(!e.contains("panicked"), "{args:?}: {e}");
        assert_ne!(o.status.code(), Some(101), "{args:?}: {e}");
    }
}

#[test]
fn long_renders_print_an_estimate_and_stop_at_max_seconds() {
    let dir = tmp("render-long");
    let scene = dir.join("s.json");
    std::fs::write(
        &scene,
        r#"{"camera": {"width": 32, "height": 32},
            "lights": [{"sphere_light": {"position": [0, 3, -2], "radius": 0.5, "intensity": 4}}],
            "objects": [{"shape": {"sphere": {}}}],
            "render": {"integrator": "path", "samples_per_pixel": 65536, "max_bounces": 64}}"#,
    )
    .unwrap();
    // An AOV folder inside one of the user's: neither the new folders nor the user's are left
    // behind changed when the render stops early.
    std::fs::create_dir(dir.join("mine")).unwrap();
    let start = std::time::Instant::now();
    let o = marchmesh(
        &[
            "render",
            scene.to_str().unwrap(),
            "--out",
            "a.png",
            "--aov",
            "mine/new/aov",
            "--max-seconds",
            "2",
        ],
        &dir,
    );
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("up to") && e.contains("rays"), "{e}");
    assert!(
        e.contains("--max-seconds 2") && e.contains("nothing was written"),
        "{e}"
    );
    assert!(start.elapsed() < std::time::Duration::from_secs(60));
    assert!(!dir.join("a.png").exists());
    assert!(dir.join("mine").is_dir() && !dir.join("mine/new").exists());
}

#[test]
fn a_failed_render_leaves_no_aov_folder_it_made_and_keeps_the_users() {
    let dir = tmp("render-aov-failed");
    std::fs::write(
        dir.join("s.json"),
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"sphere": {}}}]}"#,
    )
    .unwrap();
    // The image cannot be published (a file is in its place), so the AOVs are not either.
    std::fs::write(dir.join("a.png"), b"mine").unwrap();
    std::fs::create_dir(dir.join("kept")).unwrap();
    for aov in ["new/aov", "kept"] {
        let o = marchmesh(&["render", "s.json", "-o", "a.png", "--aov", aov], &dir);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("already exists"), "{}", stderr(&o));
    }
    assert!(!dir.join("new").exists());
    assert!(dir.join("kept").is_dir());
    assert_eq!(std::fs::read(dir.join("a.png")).unwrap(), b"mine");
    // A render that succeeds makes the folders and fills them.
    let o = marchmesh(
        &["render", "s.json", "-o", "b.png", "--aov", "new/aov"],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_dir(dir.join("new/aov")).unwrap().count() > 0);
    // The image may go into a folder that making the AOV folder makes.
    let o = marchmesh(
        &["render", "s.json", "-o", "new2/c.png", "--aov", "new2/aov"],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.join("new2/c.png").is_file());
}

#[test]
fn built_in_scenes_in_subfolders_are_found_by_their_listed_names() {
    let dir = tmp("render-builtin-subfolder");
    // Names as `marchmesh scenes` lists them, with a folder and with a dot.
    let o = marchmesh(
        &[
            "validate",
            "lighting/cornell-box",
            "extreme/grazing_plane_angle_deg_0.1",
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = dir.join("c.png");
    let o = marchmesh(
        &[
            "render",
            "crosscheck/shapes",
            "--width",
            "8",
            "--height",
            "8",
            "-o",
            out.to_str().unwrap(),
        ],
        &dir,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.exists());
    // A path that exists stays the user's file, even under a built-in name.
    std::fs::create_dir_all(dir.join("lighting")).unwrap();
    std::fs::write(dir.join("lighting/cornell-box"), b"{ not json").unwrap();
    let o = marchmesh(&["validate", "lighting/cornell-box"], &dir);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("lighting/cornell-box"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn bad_backend_options_are_refused_naming_the_key_typed_and_its_range() {
    let dir = tmp("render-option-keys");
    let scene = dir.join("s.json");
    std::fs::write(
        &scene,
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"sphere": {}}}]}"#,
    )
    .unwrap();
    for (backend, options, expected, internal) in [
        (
            "mesh",
            &["tess_level=13"][..],
            "tess_level must be in 0..=12",
            "FixedLevel",
        ),
        (
            "mesh",
            &["tess_chord=0"][..],
            "tess_chord must be",
            "ChordError",
        ),
        ("mesh", &["tess_px=0"][..], "tess_px must be", "ScreenError"),
        (
            "sdf",
            &["eps_px=0"][..],
            "sdf option eps_px: must be",
            "hit_epsilon",
        ),
        (
            "sdf",
            &["eps_abs=0"][..],
            "sdf option eps_abs: must be",
            "hit_epsilon",
        ),
        (
            "sdf",
            &["grid=sparse", "grid_res=513"][..],
            "sdf option grid_res: must be in",
            "mesh_grid_resolution",
        ),
        // The scene has no mesh to bake: the range is checked all the same.
        (
            "sdf",
            &["grid_res=513"][..],
            "sdf option grid_res: must be in 4..=512",
            "mesh_grid_resolution",
        ),
        (
            "sdf",
            &["grid_res=2"][..],
            "sdf option grid_res: must be in 4..=512",
            "mesh_grid_resolution",
        ),
        (
            "sdf",
            &["prune_cells=everywhere"][..],
            "option `prune_cells`: unknown variant `everywhere`, expected one of `auto`, `octree`, `root`",
            "PruneCells",
        ),
        (
            "sdf",
            &["prune_depth=9"][..],
            "sdf option prune_depth: must be in 0..=8",
            "SdfOptions",
        ),
    ] {
        let mut args = vec!["render", "s.json", "--backend", backend, "-o", "o.png"];
        for o in options {
            args.extend(["-O", o]);
        }
        let o = marchmesh(&args, &dir);
        let e = stderr(&o);
        assert!(!o.status.success(), "{options:?}");
        assert!(
            e.contains(expected) && !e.contains(internal),
            "{options:?}: {e}"
        );
        assert!(!dir.join("o.png").exists());
    }
}

#[test]
fn validate_reports_each_problem_once_at_its_own_path() {
    let dir = tmp("render-validate-paths");
    let good = r#"{"point": {"position": [2, 1, 0], "intensity": 0.5}}"#;
    let bad = r#"{"pointy": {}}"#;
    let lights = |bad_at: &[usize]| {
        (0..10)
            .map(|i| if bad_at.contains(&i) { bad } else { good })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let objects =
        r#"[{"shape": {"sphre": {}}}, {"shape": {"sphere": {}}}, {"shape": {"cube": 3}}]"#;
    for (bad_at, object_list) in [
        (&[0, 1, 2][..], "[{\"shape\": {\"sphere\": {}}}]"),
        (&[5, 8][..], objects),
    ] {
        let scene = dir.join("s.json");
        std::fs::write(
            &scene,
            format!(r#"{{"camera": {{"width": 8, "height": 8}}, "lights": [{}], "objects": {object_list}}}"#, lights(bad_at)),
        )
        .unwrap();
        let o = marchmesh(&["validate", "s.json"], &dir);
        let e = stderr(&o);
        assert!(!o.status.success());
        for i in 0..10 {
            let shown = e.matches(&format!("`lights[{i}]")).count();
            assert_eq!(shown, usize::from(bad_at.contains(&i)), "lights[{i}]: {e}");
        }
        assert!(!e.contains("missing field"), "{e}");
        if object_list == objects {
            assert!(
                e.contains("`objects[0].shape") && e.contains("`objects[2].shape"),
                "{e}"
            );
            assert!(!e.contains("`objects[1]"), "{e}");
        }
    }
}

#[test]
fn validate_reports_missing_fields_once_and_goes_on() {
    let dir = tmp("render-validate-missing");
    // The first problem is a missing field of the user's: printed once, then the search goes
    // on to the next ones.
    std::fs::write(
        dir.join("m.json"),
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"mesh": {}}},
            {"shape": {"mesh": {}}}, {"shape": {"cube": {}}}]}"#,
    )
    .unwrap();
    let o = marchmesh(&["validate", "m.json"], &dir);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert_eq!(e.matches("`objects[0].shape.mesh").count(), 1, "{e}");
    assert_eq!(e.matches("`objects[1].shape.mesh").count(), 1, "{e}");
    assert_eq!(e.matches("`objects[2].shape").count(), 1, "{e}");
}

#[test]
fn a_value_over_the_magnitude_limit_is_one_problem() {
    // Not also "must be > 0, got 0" for the value the limit check replaced.
    let dir = tmp("render-validate-magnitude");
    std::fs::write(
        dir.join("b.json"),
        r#"{"camera": {"width": 8, "height": 8}, "objects": [{"shape": {"smooth_union": {
            "blend_radius": -1e308, "children": [{"shape": {"sphere": {}}}]}}}]}"#,
    )
    .unwrap();
    let o = marchmesh(&["validate", "b.json"], &dir);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert_eq!(e.matches("blend_radius").count(), 1, "{e}");
    assert!(e.contains("magnitude limit") && !e.contains("got 0"), "{e}");
}

#[test]
fn max_seconds_covers_a_slow_build() {
    let dir = tmp("render-slow-build");
    // A left-deep chain of 16,000 smooth subtractions: the mesh backend samples the whole
    // chain at every grid point, a build of tens of seconds even in a release build.
    let levels = 16_000;
    let mut json = String::from(r#"{"camera": {"width": 16, "height": 16}, "objects": ["#);
    for _ in 0..levels {
        json.push_str(r#"{"shape": {"smooth_subtraction": {"blend_radius": 0.05, "children": ["#);
    }
    json.push_str(r#"{"shape": {"sphere": {"radius": 0.5}}}"#);
    for _ in 0..levels {
        json.push_str(
            r#", {"shape": {"capsule": {"radius": 0.1, "height": 0.5}}, "transform": {"translate": [0.3, 0, 0]}}]}}}"#,
        );
    }
    json.push_str("]}");
    std::fs::write(dir.join("chain.json"), json).unwrap();
    let start = std::time::Instant::now();
    let o = marchmesh(
        &[
            "render",
            "chain.json",
            "--backend",
            "mesh",
            "--out",
            "a.png",
            "--max-seconds",
            "1",
        ],
        &dir,
    );
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("--max-seconds 1") && e.contains("nothing was written"),
        "{e}"
    );
    // Parsing and the deadline, not the build's tens of seconds.
    assert!(
        start.elapsed() < std::time::Duration::from_secs(20),
        "{:?}",
        start.elapsed()
    );
    assert!(!dir.join("a.png").exists());
}

#[test]
fn an_error_thousands_of_levels_deep_names_a_shortened_path() {
    let dir = tmp("render-deep-error");
    let levels = 5_000;
    let mut json = String::from(r#"{"objects": ["#);
    for _ in 0..levels {
        json.push_str(r#"{"shape": {"union": {"children": ["#);
    }
    json.push_str(r#"{"shape": {"sphre": {}}}"#);
    for _ in 0..levels {
        json.push_str("]}}}");
    }
    json.push_str("]}");
    std::fs::write(dir.join("deep.json"), json).unwrap();
    let o = marchmesh(&["validate", "deep.json"], &dir);
    let e = stderr(&o);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains("sphre") && e.contains("characters)..."), "{e}");
    assert!(e.len() < 4_000, "{} bytes of message", e.len());
}
