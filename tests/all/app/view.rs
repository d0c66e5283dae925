//! `verisplat view` over its WebSocket, as a page uses it: frames equal `verisplat render` of
//! the same camera and settings bit for bit; every bad message is refused with an error
//! to its sender while the server and other tabs go on; keyframes exported by the viewer
//! render with `render --cameras` to the frames the viewer shows at them.
//!
//! Frames are compared with `render` on the same renderer: the Vulkan pipeline (lavapipe
//! in CI) and the CPU reference (`--cpu`). The other tests use the CPU reference: exact
//! and the same on every machine.

mod refusals;

use crate::common;
use crate::common::viewer::{diff, read_rgb, verisplat_ok, Client, Incoming, Viewer};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Duration;

const WAIT: Duration = Duration::from_secs(60);

/// Three cameras of an orbit around the demo robot at 96x64, as an INRIA cameras.json.
fn cameras(dir: &Path) -> PathBuf {
    let file = dir.join("cams.json");
    verisplat_ok(
        dir,
        &[
            "render",
            "--demo",
            "--cpu",
            "--quiet",
            "--orbit",
            "3",
            "--width",
            "96",
            "--height",
            "64",
            "--export-cameras",
            "cams.json",
            "-o",
            "orbit/f_{}.png",
        ],
    );
    file
}

/// `verisplat render --demo --cpu --cameras cams.json --camera K EXTRA` as RGB.
fn render_camera(dir: &Path, k: usize, extra: &[&str], name: &str) -> image::RgbImage {
    render_camera_on(dir, &["--cpu"], k, extra, name)
}

/// `verisplat render --demo BACKEND --cameras cams.json --camera K EXTRA` as RGB.
fn render_camera_on(
    dir: &Path,
    backend: &[&str],
    k: usize,
    extra: &[&str],
    name: &str,
) -> image::RgbImage {
    let out = format!("{name}.png");
    let ks = k.to_string();
    let mut args = vec![
        "render",
        "--demo",
        "--quiet",
        "--overwrite",
        "--cameras",
        "cams.json",
        "--camera",
        &ks,
        "-o",
        &out,
    ];
    args.extend_from_slice(backend);
    args.extend_from_slice(extra);
    verisplat_ok(dir, &args);
    read_rgb(&dir.join(out))
}

fn assert_same(got: &image::RgbImage, want: &image::RgbImage, what: &str) {
    let (n, max) = diff(got, want);
    assert_eq!(
        n, 0,
        "{what}: {n} pixels differ (by up to {max}) from verisplat render"
    );
    // Not a blank picture that would equal another blank picture.
    assert!(
        want.pixels().filter(|p| p.0 != [0, 0, 0]).count() > 100,
        "{what}: the reference shows nothing"
    );
}

#[test]
fn resting_frames_equal_render_bit_for_bit_on_the_gpu() {
    resting_frames_equal_render(&[]);
}

#[test]
fn resting_frames_equal_render_bit_for_bit_on_the_cpu() {
    resting_frames_equal_render(&["--cpu"]);
}

fn resting_frames_equal_render(backend: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    cameras(d);
    let mut args = vec!["--demo", "--cameras", "cams.json"];
    args.extend_from_slice(backend);
    // The Vulkan validation layer watches the GPU viewer (common::cli turns it on); it
    // prints what it finds.
    let viewer = Viewer::start(d, &args);
    let mut c = viewer.connect();
    let hello = c.hello.clone();
    check_hello(&hello);
    selected_camera_and_screenshots_equal_render(&mut c, d, backend);
    views_equal_render_with_its_flags(&mut c, d, backend);
    previews_while_moving(&mut c, d, backend);
    let err: Vec<String> = viewer.stderr.try_iter().collect();
    assert!(
        !err.iter().any(|l| l.contains("[vulkan")),
        "validation messages: {err:?}"
    );
}

/// The hello message: the cameras, the scene's counts and up, and the max-scale range and
/// histogram.
fn check_hello(hello: &Value) {
    assert_eq!(hello["cameras"].as_array().map(Vec::len), Some(3));
    assert_eq!(hello["gaussians"], 1873);
    assert_eq!(hello["sh_degree"], 2);
    assert_eq!(hello["up"], json!([0.0, -1.0, 0.0]));
    let [lo, hi] =
        [&hello["max_scale_range"][0], &hello["max_scale_range"][1]].map(|v| v.as_f64().unwrap());
    assert!(0.0 < lo && lo < hi, "{lo} {hi}");
    let hist = &hello["max_scale_histogram"];
    let counts: Vec<u64> = hist["counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_u64().unwrap())
        .collect();
    assert_eq!(hist["edges"].as_array().unwrap().len(), counts.len() + 1);
    assert_eq!(counts.iter().sum::<u64>(), 1873);
    assert_eq!(hist["edges"][0].as_f64(), Some(lo));
}

/// `select_camera` snaps to a camera with its intrinsics and size, and screenshots of the
/// view (PNG, EXR) equal render's output.
fn selected_camera_and_screenshots_equal_render(c: &mut Client, d: &Path, backend: &[&str]) {
    let render_camera =
        |d: &Path, k, extra: &[&str], name: &str| render_camera_on(d, backend, k, extra, name);
    // select_camera snaps to camera 1 with its intrinsics and size.
    let seq = c.send(json!({"type": "select_camera", "index": 1}));
    let snapped = c.text("camera", WAIT);
    assert_eq!(snapped["index"], 1);
    assert_eq!(snapped["camera"]["width"], 96);
    let frame = c.frame(seq, true, WAIT);
    assert_eq!(frame.header["encoding"], "png");
    assert_eq!(
        (
            frame.header["width"].as_u64(),
            frame.header["height"].as_u64()
        ),
        (Some(96), Some(64))
    );
    assert!(frame.header["visible"].as_u64().unwrap() > 0);
    assert!(frame.header["pairs"].as_u64().unwrap() > 0);
    for stage in [
        "preprocess",
        "order",
        "scan",
        "keys",
        "sort",
        "ranges",
        "blend",
        "readback",
        "total",
    ] {
        assert!(
            frame.header["timings"][stage].is_number(),
            "stage {stage} missing"
        );
    }
    assert_same(
        &frame.rgb(),
        &render_camera(d, 1, &[], "cam1"),
        "select_camera 1",
    );

    // A screenshot of the view: PNG as render writes it, EXR with the five channels.
    let seq = c.send(json!({"type": "screenshot", "format": "png"}));
    let shot = c.frame_of_kind("screenshot", seq, WAIT);
    assert_eq!(shot.header["format"], "png");
    assert_same(
        &shot.rgb(),
        &render_camera(d, 1, &[], "cam1"),
        "PNG screenshot",
    );
    let seq = c.send(json!({"type": "screenshot", "format": "exr"}));
    let shot = c.frame_of_kind("screenshot", seq, WAIT);
    assert!(shot.header["filename"].as_str().unwrap().ends_with(".exr"));
    std::fs::write(d.join("shot.exr"), &shot.payload).unwrap();
    let mut exr = vec![
        "render",
        "--demo",
        "--quiet",
        "--cameras",
        "cams.json",
        "--camera",
        "1",
        "-o",
        "ref.exr",
    ];
    exr.extend_from_slice(backend);
    verisplat_ok(d, &exr);
    let o = verisplat_ok(d, &["compare", "shot.exr", "ref.exr"]);
    let report = String::from_utf8_lossy(&o.stdout);
    assert!(report.contains("inf"), "identical EXRs: {report}");
}

/// `select_camera` at another size, and views with settings (max scale, SH degree,
/// background, modes) equal render with the matching flags.
fn views_equal_render_with_its_flags(c: &mut Client, d: &Path, backend: &[&str]) {
    let render_camera =
        |d: &Path, k, extra: &[&str], name: &str| render_camera_on(d, backend, k, extra, name);
    // select_camera at another size, as render --width resizes it.
    let seq = c.send(json!({"type": "select_camera", "index": 0, "width": 72}));
    let frame = c.frame(seq, true, WAIT);
    assert_same(
        &frame.rgb(),
        &render_camera(d, 0, &["--width", "72"], "cam0w72"),
        "select_camera 0 at width 72",
    );

    // A camera entry with a max-scale filter, SH degree 1 and a background, as render's
    // flags.
    let settings = json!({"max_scale": 0.02, "sh_degree": 1, "background": [0.25, 0.5, 1.0]});
    let seq = c.send(json!({"type": "view", "camera": c.camera(2), "settings": settings}));
    let frame = c.frame(seq, true, WAIT);
    assert_same(
        &frame.rgb(),
        &render_camera(
            d,
            2,
            &[
                "--max-scale",
                "0.02",
                "--sh-degree",
                "1",
                "--background",
                "0.25,0.5,1",
            ],
            "cam2filtered",
        ),
        "view of camera 2 with max_scale 0.02",
    );
    // The filter changed the picture (so the comparison above could fail).
    let unfiltered = render_camera(d, 2, &["--background", "0.25,0.5,1"], "cam2");
    assert!(diff(&frame.rgb(), &unfiltered).0 > 0);

    // Alpha and depth modes as render --mode alpha / depth.
    for mode in ["alpha", "depth"] {
        let seq =
            c.send(json!({"type": "view", "camera": c.camera(2), "settings": {"mode": mode}}));
        let frame = c.frame(seq, true, WAIT);
        assert_same(
            &frame.rgb(),
            &render_camera(d, 2, &["--mode", mode], mode),
            mode,
        );
    }
}

/// While moving: JPEG previews, the rest frame, and a canvas over --max-resolution scaled
/// down.
fn previews_while_moving(c: &mut Client, d: &Path, backend: &[&str]) {
    let render_camera =
        |d: &Path, k, extra: &[&str], name: &str| render_camera_on(d, backend, k, extra, name);
    // While moving: a JPEG preview; without a `rest` the full frame follows by itself.
    // (Settings left out are the last ones sent: back to the defaults.)
    let seq =
        c.send(json!({"type": "view", "camera": c.camera(0), "settings": {}, "interactive": true}));
    let preview = c.frame(seq, false, WAIT);
    assert_eq!(preview.header["encoding"], "jpeg");
    let full = c.frame(seq, true, WAIT);
    assert_same(&full.rgb(), &render_camera(d, 0, &[], "cam0"), "rest frame");

    // A canvas over --max-resolution is scaled down with its aspect ratio.
    let mut big = c.camera(0);
    big["width"] = 3840.into();
    big["height"] = 2560.into();
    big["fx"] = (big["fx"].as_f64().unwrap() * 40.0).into();
    big["fy"] = (big["fy"].as_f64().unwrap() * 40.0).into();
    let seq = c.send(json!({"type": "view", "camera": big, "interactive": true}));
    let preview = c.frame(seq, false, WAIT);
    let (w, h) = (
        preview.header["width"].as_u64().unwrap(),
        preview.header["height"].as_u64().unwrap(),
    );
    assert!(w * h <= 250_000 && w * 2 == h * 3, "preview {w}x{h}");
}

/// The splat scale factor and the filters against `render --scale-modifier` and the
/// filter flags, on both renderers.
#[test]
fn scale_modifier_frame_equals_render_with_scale_modifier() {
    scale_modifier_equals_render(&[]);
    scale_modifier_equals_render(&["--cpu"]);
}

fn scale_modifier_equals_render(backend: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    cameras(d);
    let mut args = vec!["--demo", "--cameras", "cams.json"];
    args.extend_from_slice(backend);
    let viewer = Viewer::start(d, &args);
    let render_camera =
        |d: &Path, k, extra: &[&str], name: &str| render_camera_on(d, backend, k, extra, name);
    let mut c = viewer.connect();
    let seq =
        c.send(json!({"type": "view", "camera": c.camera(1), "settings": {"scale_modifier": 0.6}}));
    let frame = c.frame(seq, true, WAIT);
    assert_same(
        &frame.rgb(),
        &render_camera(d, 1, &["--scale-modifier", "0.6"], "cam1s06"),
        "scale_modifier 0.6",
    );
    assert!(diff(&frame.rgb(), &render_camera(d, 1, &[], "cam1")).0 > 0);
    // Every slider at once.
    let settings =
        json!({"scale_modifier": 1.7, "min_opacity": 0.3, "max_scale": 0.05, "sh_degree": 0});
    let seq = c.send(json!({"type": "view", "camera": c.camera(0), "settings": settings}));
    let frame = c.frame(seq, true, WAIT);
    assert_same(
        &frame.rgb(),
        &render_camera(
            d,
            0,
            &[
                "--scale-modifier",
                "1.7",
                "--min-opacity",
                "0.3",
                "--max-scale",
                "0.05",
                "--sh-degree",
                "0",
            ],
            "cam0all",
        ),
        "all settings",
    );
}

#[test]
fn closed_tabs_free_their_state_and_http_serves_the_page() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let viewer = Viewer::start(dir.path(), &["--demo", "--cpu", "--width", "48"]);
    // More tabs than the server holds at once (16), one after the other: each closed
    // tab's slot is freed, so every one connects.
    for i in 0..24 {
        let mut c = viewer.connect();
        let cam = c.camera(0);
        assert_eq!(cam["width"], 48, "--width applies to the camera list");
        if i % 8 == 0 {
            let seq = c.send(json!({"type": "view", "camera": cam}));
            c.frame(seq, true, WAIT);
        }
        c.ws.close(None).unwrap();
        // Until the server has seen the close.
        while c.ws.read().is_ok() {}
        std::thread::sleep(Duration::from_millis(30));
    }
    // Sockets that never send a request (more than the server keeps) do not stop it.
    let idle: Vec<std::net::TcpStream> = (0..100)
        .filter_map(|_| std::net::TcpStream::connect(("127.0.0.1", viewer.port)).ok())
        .collect();
    assert!(idle.len() > 64);
    drop(idle);
    // Their threads see the end of the stream at once; give them a moment to go.
    std::thread::sleep(Duration::from_millis(500));
    let mut c = viewer.connect();
    let seq = c.send(json!({"type": "view", "camera": c.camera(0)}));
    c.frame(seq, true, WAIT);
    let get = |path: &str| {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", viewer.port)).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        write!(s, "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        let mut out = String::new();
        let _ = s.read_to_string(&mut out);
        out
    };
    let index = get("/");
    assert!(index.starts_with("HTTP/1.1 200"), "{index}");
    assert!(index.contains("viewer.js"));
    assert!(get("/viewer.js").contains("verisplatViewer"));
    assert!(get("/viewer.css").contains("text/css"));
    assert!(get("/etc/passwd").starts_with("HTTP/1.1 404"));
    assert!(get("/../Cargo.toml").starts_with("HTTP/1.1 404"));
    // Another host name (a rebound DNS name) is refused.
    let mut s = std::net::TcpStream::connect(("127.0.0.1", viewer.port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET / HTTP/1.1\r\nHost: evil.example:{}\r\n\r\n",
        viewer.port
    )
    .unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    assert!(out.starts_with("HTTP/1.1 403"), "{out}");
    // A WebSocket from another site's page is refused.
    let mut s = std::net::TcpStream::connect(("127.0.0.1", viewer.port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(s, "GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nOrigin: http://evil.example\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n", viewer.port).unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    assert!(out.starts_with("HTTP/1.1 403"), "{out}");
    // So is one naming another host (the WebSocket handshake's own check).
    let mut s = std::net::TcpStream::connect(("127.0.0.1", viewer.port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(s, "GET /ws HTTP/1.1\r\nHost: evil.example:{}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n", viewer.port).unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    assert!(out.starts_with("HTTP/1.1 403"), "{out}");
    assert!(out.contains("localhost names"), "{out}");
}

/// A scene of at most twice the preview subset no longer previews whole (it used to:
/// the 31k robot previewed slower than the 125k one): the first preview draws the
/// subset's most important Gaussians, later ones as many as the stage times allow
/// (issue 29, item 3).
#[test]
fn a_scene_under_twice_the_subset_previews_a_subset() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    verisplat_ok(d, &["gen", "15000", "--seed", "3", "-o", "scene.ply"]);
    let viewer = Viewer::start(d, &["scene.ply", "--preview-gaussians", "10000"]);
    let mut c = viewer.connect();
    let cam = c.hello["initial_camera"].clone();
    let seq = c.send(json!({"type": "view", "camera": cam, "interactive": true}));
    let preview = c.frame(seq, false, WAIT);
    assert_eq!(preview.header["gaussians"], 10000, "{}", preview.header);
    // The view at rest draws every Gaussian.
    let full = c.frame(seq, true, WAIT);
    assert_eq!(full.header["gaussians"], 15000);
    // Later previews draw the subset or the whole scene, nothing between.
    for k in 0..5 {
        let mut moved = cam.clone();
        moved["position"][0] = (cam["position"][0].as_f64().unwrap() + 0.01 * k as f64).into();
        let seq = c.send(json!({"type": "view", "camera": moved, "interactive": true}));
        let g = c.frame(seq, false, WAIT).header["gaussians"]
            .as_u64()
            .unwrap();
        assert!((8192..=10000).contains(&g) || g == 15000, "{g}");
    }
}

/// Context switches of every thread of process `pid` so far (Linux).
fn context_switches(pid: u32) -> u64 {
    let mut total = 0;
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).unwrap() {
        let status =
            std::fs::read_to_string(task.unwrap().path().join("status")).unwrap_or_default();
        for line in status.lines() {
            if line.starts_with("voluntary_ctxt_switches:")
                || line.starts_with("nonvoluntary_ctxt_switches:")
            {
                total += line
                    .split_whitespace()
                    .nth(1)
                    .and_then(|n| n.parse::<u64>().ok())
                    .unwrap_or(0);
            }
        }
    }
    total
}

/// The tab limit is answered with HTTP 503; pings are answered with their payload; a
/// client's close is answered with a close and frees its slot; an idle server with open
/// tabs sleeps (nothing polls: no wake-ups while nothing happens).
#[test]
fn tab_limit_pings_closes_and_an_idle_server() {
    use std::io::{Read, Write};
    use tungstenite::Message;
    let dir = tempfile::tempdir().unwrap();
    let viewer = Viewer::start(dir.path(), &["--demo", "--cpu", "--width", "32"]);
    let mut tabs: Vec<Client> = (0..16).map(|_| viewer.connect()).collect();
    let cam = tabs[0].camera(0);
    let seq = tabs[0].send(json!({"type": "view", "camera": cam}));
    tabs[0].frame(seq, true, WAIT);
    let handshake = format!("GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n", viewer.port);
    let mut s = std::net::TcpStream::connect(("127.0.0.1", viewer.port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(handshake.as_bytes()).unwrap();
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    assert!(out.starts_with("HTTP/1.1 503"), "{out}");
    assert!(out.contains("too many viewer tabs"), "{out}");

    // Idle: the 16 tabs, the listener and the worker wait without waking. (The server
    // used to poll every 10 ms: some 1,700 switches a second here.)
    std::thread::sleep(Duration::from_millis(500));
    let pid = viewer.child.id();
    let before = context_switches(pid);
    std::thread::sleep(Duration::from_secs(2));
    let switches = context_switches(pid) - before;
    assert!(
        switches < 20,
        "{switches} context switches in 2 s of idling"
    );

    let c = &mut tabs[3];
    c.ws.send(Message::Ping(b"are you there".to_vec().into()))
        .unwrap();
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        assert!(std::time::Instant::now() < deadline, "no pong");
        match c.ws.read() {
            Ok(Message::Pong(data)) => {
                assert_eq!(&data[..], b"are you there");
                break;
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("WebSocket failed: {e}"),
        }
    }
    c.ws.close(None).unwrap();
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        assert!(
            std::time::Instant::now() < deadline,
            "no answer to the close"
        );
        match c.ws.read() {
            // tungstenite reports the server's close as the end of the connection.
            Err(tungstenite::Error::ConnectionClosed) => break,
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("the close was not answered: {e}"),
        }
    }
    // Its slot is free: a 16th tab connects again and is served.
    tabs.remove(3);
    let mut c = viewer.connect();
    let seq = c.send(json!({"type": "view", "camera": c.camera(0)}));
    c.frame(seq, true, WAIT);
}

#[test]
fn sigterm_stops_the_server_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let mut viewer = Viewer::start(dir.path(), &["--demo", "--cpu", "--width", "64"]);
    let mut c = viewer.connect();
    let seq = c.send(json!({"type": "view", "camera": c.camera(0)}));
    c.frame(seq, true, WAIT);
    let pid = viewer.child.id().to_string();
    let o = std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .output()
        .unwrap();
    assert!(o.status.success());
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(s) = viewer.child.try_wait().unwrap() {
            break s;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the server did not stop"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success(), "{status:?}");
    let err: Vec<String> = viewer.stderr.try_iter().collect();
    assert!(err.iter().any(|l| l.contains("viewer stopped")), "{err:?}");
    // The page's connection was closed, not left hanging.
    let closed = (0..100).any(|_| match c.ws.read() {
        Ok(tungstenite::Message::Close(_)) | Err(tungstenite::Error::ConnectionClosed) => true,
        Err(tungstenite::Error::Io(e)) => !matches!(
            e.kind(),
            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
        ),
        Err(_) => true,
        Ok(_) => false,
    });
    assert!(closed);
}

/// `--open` runs xdg-open with the URL; an xdg-open that fails is a note, the server
/// goes on.
#[test]
fn open_runs_xdg_open_with_the_url() {
    use std::os::unix::fs::PermissionsExt;
    for works in [true, false] {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let bin = d.join("bin");
        std::fs::create_dir(&bin).unwrap();
        let script = bin.join("xdg-open");
        let log = d.join("opened.txt");
        std::fs::write(
            &script,
            format!(
                "#!/bin/sh\necho \"$1\" > '{}'\nexit {}\n",
                log.display(),
                if works { 0 } else { 3 }
            ),
        )
        .unwrap();
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
        let path = format!(
            "{}:{}",
            bin.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        let mut viewer = Viewer::start_with_env(
            d,
            &["--demo", "--cpu", "--open"],
            &[("PATH", path.as_str())],
        );
        let deadline = std::time::Instant::now() + WAIT;
        while !log.exists() {
            assert!(std::time::Instant::now() < deadline, "xdg-open never ran");
            std::thread::sleep(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_millis(200));
        let opened = std::fs::read_to_string(&log).unwrap();
        assert_eq!(opened.trim(), viewer.url);
        if !works {
            let deadline = std::time::Instant::now() + WAIT;
            let mut err = Vec::new();
            while !err
                .iter()
                .any(|l: &String| l.contains("xdg-open could not open"))
            {
                assert!(std::time::Instant::now() < deadline, "no note: {err:?}");
                err.extend(viewer.stderr.try_iter());
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        assert!(viewer.alive());
        let mut c = viewer.connect();
        let seq = c.send(json!({"type": "view", "camera": c.camera(0)}));
        c.frame(seq, true, WAIT);
    }
}

#[test]
fn port_in_use_is_one_clear_error() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let o = std::process::Command::new(common::cli::bin())
        .args(["view", "--demo", "--cpu", "--port", &port])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(!e.contains("panicked"), "{e}");
    assert!(
        e.starts_with("error: ") && e.contains(&format!("port {port}")) && e.contains("in use"),
        "{e}"
    );
}

#[test]
fn exported_keyframes_render_to_what_the_viewer_shows() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    cameras(d);
    let viewer = Viewer::start(d, &["--demo", "--cpu", "--cameras", "cams.json"]);
    let mut c = viewer.connect();
    let keyframes: Vec<Value> = (0..3)
        .map(|k| json!({"time": k as f64, "camera": c.camera(k)}))
        .collect();
    c.send(
        json!({"type": "export_keyframes", "format": "verisplat", "fps": 2, "keyframes": keyframes}),
    );
    let export = c.text("export", WAIT);
    assert_eq!(export["filename"], "keyframes.json");
    std::fs::write(d.join("keyframes.json"), export["text"].as_str().unwrap()).unwrap();
    // fps 2: keyframes at 0, 1, 2 s are frames 0, 2, 4.
    verisplat_ok(
        d,
        &[
            "render",
            "--demo",
            "--cpu",
            "--quiet",
            "--cameras",
            "keyframes.json",
            "-o",
            "path/f_{:05}.png",
        ],
    );
    let frames: Vec<PathBuf> = (0..5)
        .map(|k| d.join(format!("path/f_{k:05}.png")))
        .collect();
    assert!(frames.iter().all(|f| f.exists()));
    assert!(!d.join("path/f_00005.png").exists());
    let shown: Vec<image::RgbImage> = (0..3)
        .map(|k| {
            let seq = c.send(json!({"type": "view", "camera": export["cameras"][k]}));
            c.frame(seq, true, WAIT).rgb()
        })
        .collect();
    for (k, img) in shown.iter().enumerate() {
        assert_same(img, &read_rgb(&frames[2 * k]), &format!("keyframe {k}"));
        // The keyframe is the camera it was made from (up to the file's rounding).
        let (n, max) = diff(img, &render_camera(d, k, &[], &format!("cam{k}")));
        assert!(
            max <= 2 && n < 96 * 64 / 50,
            "keyframe {k}: {n} pixels by {max}"
        );
    }
    // The page's preview plays the frames the server samples: those render makes.
    c.send(json!({"type": "sample_keyframes", "fps": 2, "keyframes": keyframes}));
    let path = c.text("path", WAIT);
    assert_eq!(path["cameras"].as_array().map(Vec::len), Some(5));
    for k in [1, 3] {
        let seq = c.send(json!({"type": "view", "camera": path["cameras"][k]}));
        let shown = c.frame(seq, true, WAIT).rgb();
        assert_same(&shown, &read_rgb(&frames[k]), &format!("path frame {k}"));
    }

    // nerfstudio's camera_path.json: the same path sampled at 2 frames/s.
    c.send(json!({"type": "export_keyframes", "format": "nerfstudio", "fps": 2, "keyframes": keyframes}));
    let ns = c.text("export", WAIT);
    assert_eq!(ns["filename"], "camera_path.json");
    std::fs::write(d.join("camera_path.json"), ns["text"].as_str().unwrap()).unwrap();
    verisplat_ok(
        d,
        &[
            "render",
            "--demo",
            "--cpu",
            "--quiet",
            "--cameras",
            "camera_path.json",
            "-o",
            "ns/f_{:05}.png",
        ],
    );
    for (k, img) in shown.iter().enumerate() {
        let (n, max) = diff(&read_rgb(&d.join(format!("ns/f_{:05}.png", 2 * k))), img);
        assert!(
            max <= 2 && n < 96 * 64 / 50,
            "nerfstudio frame {}: {n} pixels by {max}",
            2 * k
        );
    }
    assert!(!d.join("ns/f_00005.png").exists());
}

/// Interactive rate with the shared scenes on the Vulkan pipeline (without the
/// validation layer, as a user runs it): a client that keeps the camera moving, as a drag
/// does, for 5 s on a 1280x720 canvas. Prints, per scene, the preview frames per second,
/// the last preview's size and Gaussians, and the mean GPU time of the previews; a
/// smaller scene must not preview slower than a larger one by more than the noise of a
/// shared machine (issue 29, item 3). Run with `--ignored` (needs ../shared/data); the
/// figures are in BENCHMARKS.md.
#[test]
#[ignore]
fn preview_rate_of_the_shared_scenes() {
    let scenes = [
        "playbot_lod3_31k_sh2.ply",
        "playbot_lod2_125k_sh2.ply",
        "playbot_lod1_250k_sh1.ply",
    ];
    let rates: Vec<f64> = scenes.iter().map(|s| preview_rate(s, &[])).collect();
    preview_rate("playbot_lod2_125k_sh2.ply", &["--cpu"]);
    for pair in rates.windows(2) {
        assert!(
            pair[0] > 0.85 * pair[1],
            "a smaller scene previews slower: {rates:?}"
        );
    }
}

/// Preview frames per second of `scene` during 5 s of camera moves.
fn preview_rate(scene: &str, backend: &[&str]) -> f64 {
    let scene = common::shared_data().join(scene);
    let dir = tempfile::tempdir().unwrap();
    let mut args = vec![scene.to_str().unwrap()];
    args.extend_from_slice(backend);
    let viewer = Viewer::start_with_env(dir.path(), &args, &[("VERISPLAT_VALIDATE", "0")]);
    let mut c = viewer.connect();
    let mut cam = c.hello["initial_camera"].clone();
    let scale = 1280.0 / cam["width"].as_f64().unwrap();
    cam["width"] = 1280.into();
    cam["height"] = 720.into();
    for k in ["fx", "fy"] {
        cam[k] = (cam[k].as_f64().unwrap() * scale).into();
    }
    for k in ["cx", "cy"] {
        if let Some(v) = cam[k].as_f64() {
            cam[k] = (v * scale).into();
        }
    }
    let start = std::time::Instant::now();
    let (mut previews, mut fulls, mut k) = (0, 0, 0.0f64);
    let mut gpu_ms = Vec::new();
    let mut size = String::new();
    // As a page during a drag: a move every 30 ms, frames read in between.
    while start.elapsed() < Duration::from_secs(5) {
        k += 0.01;
        let mut moved = cam.clone();
        moved["position"][0] = (cam["position"][0].as_f64().unwrap() + k * 0.1).into();
        c.send(json!({"type": "view", "camera": moved, "interactive": true}));
        let next_move = std::time::Instant::now() + Duration::from_millis(30);
        while std::time::Instant::now() < next_move {
            if let Some(Incoming::Frame(f)) = c.next(Duration::from_millis(5)) {
                if f.full() {
                    fulls += 1;
                } else {
                    previews += 1;
                    let total = f.header["timings"]["total"].as_f64().unwrap_or(0.0);
                    gpu_ms.push(total);
                    size = format!(
                        "{}x{} of {} Gaussians (wall {:.1} ms, GPU {:.1} ms: {})",
                        f.header["width"],
                        f.header["height"],
                        f.header["gaussians"],
                        f.header["wall_ms"].as_f64().unwrap_or(0.0),
                        total,
                        f.header["timings"]
                    );
                }
            }
        }
    }
    let rate = previews as f64 / start.elapsed().as_secs_f64();
    let mean_gpu = gpu_ms.iter().sum::<f64>() / gpu_ms.len().max(1) as f64;
    println!(
        "{} {backend:?}: {rate:.1} preview frames/s (mean GPU {mean_gpu:.1} ms), the last {size}, {fulls} full frames",
        scene.file_name().unwrap().to_string_lossy()
    );
    assert!(rate > 0.0);
    assert_eq!(fulls, 0, "a full frame was rendered while the camera moved");
    rate
}
