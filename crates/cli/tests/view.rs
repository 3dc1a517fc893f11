//! Issue 19: `marchmesh view`. The headless script mode moves the camera as scripted, its
//! refined frames equal one-off `marchmesh render`s of the cameras it saves (P), hostile
//! scripts and outputs are refused with clear errors, and the real window opens under a
//! virtual X server when one is installed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use marchmesh_testkit::run_program;

const BIN: &str = env!("CARGO_BIN_EXE_marchmesh");

fn seed_spheres() -> String {
    marchmesh_testkit::scenes_dir()
        .join("seed-spheres.json")
        .display()
        .to_string()
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Largest difference of any channel of any pixel in the columns `cols` of two images.
fn max_diff(a: &image::RgbImage, b: &image::RgbImage, cols: std::ops::Range<u32>) -> u8 {
    assert_eq!(a.dimensions(), b.dimensions());
    let mut worst = 0;
    for y in 0..a.height() {
        for x in cols.clone() {
            let (p, q) = (a.get_pixel(x, y).0, b.get_pixel(x, y).0);
            for c in 0..3 {
                worst = worst.max(p[c].abs_diff(q[c]));
            }
        }
    }
    worst
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    let a = v.as_array().expect("array");
    [0, 1, 2].map(|i| a[i].as_f64().expect("number"))
}

#[test]
fn headless_script_moves_the_camera_and_refined_frames_match_one_off_renders() {
    let dir = marchmesh_testkit::temp_dir("view-script");
    let script = dir.join("script.json");
    std::fs::write(
        &script,
        r#"[
  {"key": "W", "frames": 3},
  {"mouse_drag": [40, 0]},
  {"wait": 2},
  {"key": "P"},
  {"key": "Tab"},
  {"wait": 2},
  {"key": "P"},
  {"key": "R"},
  {"wait": 2}
]"#,
    )
    .expect("write script");
    let frames = dir.join("frames");
    let scene = seed_spheres();
    let args = [
        "view",
        &scene,
        "--headless",
        "--script",
        "script.json",
        "--frames",
        "frames",
        "--width",
        "64",
        "--height",
        "48",
        "--threads",
        "2",
        "--step",
        "0.25",
    ];
    let (ok, stdout, stderr) = run_program(BIN, &args, &dir);
    assert!(ok, "view failed: {stdout}\n{stderr}");
    let listing = json(&frames.join("frames.json"));
    let list = listing["frames"].as_array().expect("frames");
    assert_eq!(
        list.len(),
        12,
        "3 W + 1 drag + 2 wait + Tab + 2 wait + R + 2 wait"
    );
    for i in 0..list.len() {
        assert!(
            frames.join(format!("frame-{i:05}.png")).is_file(),
            "frame {i}"
        );
    }
    // W moves 0.25 along the start view direction (+z) per frame; moving frames are coarse.
    for (i, f) in list.iter().take(3).enumerate() {
        let p = vec3(&f["position"]);
        let z = 0.25 * (i + 1) as f64;
        assert!(
            (p[0]).abs() < 1e-12 && p[1].abs() < 1e-12 && (p[2] - z).abs() < 1e-12,
            "{f}"
        );
        assert_eq!(f["refine"], 0);
        assert_eq!(f["scale"], 4);
        assert_eq!(f["backend"], "sdf");
    }
    // A 40-pixel drag turns 10 degrees; still frames refine to full resolution.
    assert_eq!(list[3]["yaw_deg"].as_f64(), Some(10.0));
    assert_eq!(list[3]["input"], "drag 40 0");
    assert_eq!(
        (list[4]["refine"].as_u64(), list[5]["refine"].as_u64()),
        (Some(1), Some(2))
    );
    assert_eq!(list[5]["render_size"], serde_json::json!([64, 48]));
    let accuracy = &list[5]["views"][0]["accuracy"];
    assert!(
        accuracy["silhouette_mismatch_pct"].as_f64().is_some(),
        "{accuracy}"
    );
    assert_eq!(list[5]["views"][0]["shifted"], false);
    assert_eq!(
        list[0]["views"][0]["shifted"], true,
        "moving frames reuse the first build"
    );
    // Tab splits sdf (left) with mesh (right).
    assert_eq!(list[6]["split_with"], "mesh");
    assert_eq!(list[8]["refine"], 2);
    // R goes back to the start.
    assert_eq!(vec3(&list[9]["position"]), [0.0, 0.0, 0.0]);
    assert_eq!(list[9]["yaw_deg"].as_f64(), Some(0.0));

    let shots = listing["shots"].as_array().expect("shots");
    assert_eq!(shots.len(), 2);
    assert_eq!(shots[0]["frame"], 5);
    assert_eq!(shots[1]["frame"], 8);
    // The saved camera is the frame's camera.
    let saved = json(&frames.join("shot-000.json"));
    assert_eq!(
        vec3(&saved["camera"]["position"]),
        vec3(&list[5]["position"])
    );
    assert_eq!(saved["camera"]["width"], 64);
    assert_eq!(
        rgb(&frames.join("shot-000.png")),
        rgb(&frames.join("frame-00005.png")),
        "P saves the frame shown"
    );

    // One-off renders of the saved cameras equal the refined frames.
    let one_off = |shot: &str, backend: &str, out: &str| {
        let shot = frames.join(shot).display().to_string();
        let (ok, stdout, stderr) = run_program(
            BIN,
            &[
                "render",
                &shot,
                "--backend",
                backend,
                "--out",
                out,
                "--threads",
                "2",
            ],
            &dir,
        );
        assert!(ok, "render failed: {stdout}\n{stderr}");
        rgb(&dir.join(out))
    };
    let frame5 = rgb(&frames.join("frame-00005.png"));
    let sdf = one_off("shot-000.json", "sdf", "sdf.png");
    assert!(
        max_diff(&frame5, &sdf, 0..64) <= 1,
        "sdf frame differs from marchmesh render"
    );
    let frame8 = rgb(&frames.join("frame-00008.png"));
    let sdf = one_off("shot-001.json", "sdf", "sdf1.png");
    let mesh = one_off("shot-001.json", "mesh", "mesh1.png");
    assert!(max_diff(&frame8, &sdf, 0..32) <= 1, "left half is sdf");
    assert!(max_diff(&frame8, &mesh, 32..64) <= 1, "right half is mesh");
    // Back at the start (R), the refined frame is a one-off render of the scene itself.
    let (ok, stdout, stderr) = run_program(
        BIN,
        &[
            "render",
            &scene,
            "--backend",
            "sdf",
            "--out",
            "start.png",
            "--width",
            "64",
            "--height",
            "48",
            "--threads",
            "2",
        ],
        &dir,
    );
    assert!(ok, "render failed: {stdout}\n{stderr}");
    let frame11 = rgb(&frames.join("frame-00011.png"));
    assert_eq!(list[11]["split_with"], "mesh");
    assert!(
        max_diff(&frame11, &rgb(&dir.join("start.png")), 0..32) <= 1,
        "start frame"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_baked_mesh_scene_rebuilt_at_a_new_camera_matches_a_one_off_render() {
    // The sdf backend bakes meshes into grids; the session keeps its bakes in a folder of
    // its own so still frames at a new camera rebuild without baking again. The picture
    // must not change for it, and the folder is gone afterwards.
    let dir = marchmesh_testkit::temp_dir("view-bake");
    std::fs::write(
        dir.join("s.json"),
        r#"[{"key": "W", "frames": 2}, {"wait": 2}, {"key": "P"}]"#,
    )
    .expect("write script");
    let scene = marchmesh_testkit::scenes_dir()
        .join("generated/mesh_bunny.json")
        .display()
        .to_string();
    let args = [
        "view",
        &scene,
        "--headless",
        "--script",
        "s.json",
        "--frames",
        "f",
        "--width",
        "48",
        "--height",
        "36",
        "--threads",
        "2",
        "--no-accuracy",
    ];
    // Its own temporary folder, to see what the session leaves there.
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).expect("mkdir");
    let out = Command::new(BIN)
        .args(args)
        .env("TMPDIR", &tmp)
        .current_dir(&dir)
        .output()
        .expect("run marchmesh");
    assert!(
        out.status.success(),
        "view failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let leftover: Vec<_> = std::fs::read_dir(&tmp).expect("tmp").collect();
    assert!(
        leftover.is_empty(),
        "the session's bake folder is removed: {leftover:?}"
    );
    let listing = json(&dir.join("f/frames.json"));
    let frames = listing["frames"].as_array().expect("frames");
    assert!(
        frames[2]["views"][0]["build_ms"].is_number(),
        "rebuilt when still"
    );
    let (ok, stdout, stderr) = run_program(
        BIN,
        &[
            "render",
            "f/shot-000.json",
            "--backend",
            "sdf",
            "--out",
            "one.png",
            "--threads",
            "2",
        ],
        &dir,
    );
    assert!(ok, "render failed: {stdout}\n{stderr}");
    let (a, b) = (
        rgb(&dir.join("f/frame-00003.png")),
        rgb(&dir.join("one.png")),
    );
    assert!(
        max_diff(&a, &b, 0..48) <= 1,
        "baked sdf frame differs from marchmesh render"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn hostile_scripts_and_outputs_are_clear_errors_and_nothing_is_overwritten() {
    let dir = marchmesh_testkit::temp_dir("view-hostile");
    let scene = seed_spheres();
    let run = |script: &str, frames: &str| {
        std::fs::write(dir.join("s.json"), script).expect("write script");
        let args = [
            "view",
            &scene,
            "--headless",
            "--script",
            "s.json",
            "--frames",
            frames,
            "--width",
            "16",
            "--height",
            "12",
            "--threads",
            "1",
        ];
        run_program(BIN, &args, &dir)
    };
    let cases = [
        (
            "[\n  {\"key\": \"W\"},\n  {\"key\": \"F13\"}\n]",
            "entry 1, line 3",
            "unknown key",
        ),
        ("[{\"key\": \"W\", \"wait\": 3}]", "entry 0", "exactly one"),
        ("[{\"wait\": -1}]", "entry 0", "invalid value"),
        ("[{\"mouse_drag\": [1]}]", "entry 0", "mouse_drag"),
        ("[{\"key\": \"W\"}", "line 1", "EOF"),
        ("not json", "line 1", "expected"),
        ("[]", "s.json", "no entries"),
    ];
    for (script, place, reason) in cases {
        let (ok, _, stderr) = run(script, "out");
        assert!(!ok, "{script}");
        assert!(
            stderr.contains("s.json") && stderr.contains(place) && stderr.contains(reason),
            "{script}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(!dir.join("out").exists(), "nothing written for {script}");
    }
    // Existing frames are never overwritten, and the run fails before rendering anything.
    std::fs::create_dir_all(dir.join("taken")).expect("mkdir");
    std::fs::write(dir.join("taken/frame-00001.png"), b"mine").expect("write");
    let (ok, _, stderr) = run(r#"[{"wait": 2}]"#, "taken");
    assert!(
        !ok && stderr.contains("frame-00001.png") && stderr.contains("already exists"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read(dir.join("taken/frame-00001.png")).expect("read"),
        b"mine"
    );
    assert!(!dir.join("taken/frame-00000.png").exists());
    // A missing scene or script names the file.
    let (ok, _, stderr) = run_program(
        BIN,
        &[
            "view",
            "missing.json",
            "--headless",
            "--script",
            "s.json",
            "--frames",
            "x",
        ],
        &dir,
    );
    assert!(!ok && stderr.contains("missing.json"), "{stderr}");
    let (ok, _, stderr) = run_program(
        BIN,
        &[
            "view",
            &scene,
            "--headless",
            "--script",
            "nope.json",
            "--frames",
            "x",
        ],
        &dir,
    );
    assert!(!ok && stderr.contains("nope.json"), "{stderr}");
    // A step that is not a positive number is refused.
    let (ok, _, stderr) = run_program(BIN, &["view", &scene, "--step", "0"], &dir);
    assert!(!ok && stderr.contains("--step"), "{stderr}");
    // A bad option names the backend and key.
    let (ok, _, stderr) = run_program(BIN, &["view", &scene, "--opt", "mesh:wat=1"], &dir);
    assert!(
        !ok && stderr.contains("wat") && stderr.contains("mesh"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn without_a_display_the_window_is_a_clear_error() {
    let dir = marchmesh_testkit::temp_dir("view-nodisplay");
    let out = Command::new(BIN)
        .args(["view", &seed_spheres(), "--width", "16", "--height", "12"])
        .args(["--threads", "1", "--exit-after-frames", "1"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .current_dir(&dir)
        .output()
        .expect("run marchmesh");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(
        out.status.code(),
        Some(1),
        "an error, not a crash: {stderr}"
    );
    assert!(
        stderr.contains("cannot open a window") && stderr.contains("--headless"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Kills the virtual X server when the test ends, however it ends.
struct Server(std::process::Child);

impl Drop for Server {
    fn drop(&mut self) {
        self.0.kill().ok();
        self.0.wait().ok();
    }
}

#[test]
fn the_window_opens_under_a_virtual_x_server() {
    use marchmesh_testkit::tools::{Tool, require, skip};
    const TEST: &str = "the_window_opens_under_a_virtual_x_server";
    let Some(xvfb) = require(Tool::Xvfb, TEST) else {
        return;
    };
    // A display number nobody uses: no socket and no lock file.
    let Some(n) = (90..190).find(|n| {
        !Path::new(&format!("/tmp/.X11-unix/X{n}")).exists()
            && !Path::new(&format!("/tmp/.X{n}-lock")).exists()
    }) else {
        skip(Tool::Xvfb, TEST, "no free X display number in :90..:190");
        return;
    };
    let server = Command::new(xvfb)
        .args([
            &format!(":{n}"),
            "-screen",
            "0",
            "320x240x24",
            "-nolisten",
            "tcp",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn();
    let Ok(server) = server else {
        skip(Tool::Xvfb, TEST, "Xvfb did not start");
        return;
    };
    let mut server = Server(server);
    let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
    let start = Instant::now();
    while !socket.exists() && start.elapsed() < Duration::from_secs(10) {
        if let Ok(Some(status)) = server.0.try_wait() {
            skip(
                Tool::Xvfb,
                TEST,
                &format!("Xvfb exited at start ({status})"),
            );
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    if !socket.exists() {
        skip(
            Tool::Xvfb,
            TEST,
            &format!("Xvfb did not open display :{n} within 10 s"),
        );
        return;
    }
    let dir = marchmesh_testkit::temp_dir("view-window");
    let out = Command::new(BIN)
        .args(["view", &seed_spheres(), "--width", "64", "--height", "48"])
        .args(["--threads", "1", "--exit-after-frames", "5"])
        .env("DISPLAY", format!(":{n}"))
        .current_dir(&dir)
        .output()
        .expect("run marchmesh");
    drop(server);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    if !out.status.success() && stderr.contains("failed to load") {
        skip(
            Tool::Xvfb,
            TEST,
            &format!("the X11 client libraries (libX11, libXcursor) are missing: {stderr}"),
        );
        return;
    }
    assert!(out.status.success(), "{stdout}\n{stderr}");
    // Coarse, half and full resolution, then idle updates of the refined picture.
    assert!(
        stdout.contains("window closed after 3 frames (5 updates)"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
