//! The viewer in a real browser: headless Chromium driven through WebDriver (Debian's
//! `chromium` and `chromium-driver`, installed by `tools/setup.sh`). The page is opened,
//! dragged, flown with W, its scale slider moved and a camera selected; the page's state
//! (`window.verisplatViewer`) must change as each control says, frames must keep coming,
//! and a screenshot of the page must show a rendered scene.
//!
//! `VERISPLAT_VIEWER_SCREENSHOT=path.png` also saves the page screenshot (the README's
//! docs/viewer.png is made so, with `VERISPLAT_VIEWER_SCENE=/absolute/path/scene.ply`: the
//! test runs in a temporary directory); `VERISPLAT_VIEWER_LENS=fisheye:fov=190` shows the
//! cameras through that lens.

use crate::common::viewer::{verisplat_ok, Viewer};
use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHROMEDRIVER: &str = "/usr/bin/chromedriver";
const CHROMIUM: &str = "/usr/bin/chromium";

/// One HTTP/1.1 request to chromedriver; the JSON body of the answer.
fn http(port: u16, method: &str, path: &str, body: Option<&Value>) -> Result<Value, String> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).map_err(|e| e.to_string())?;
    s.set_read_timeout(Some(Duration::from_secs(90)))
        .map_err(|e| e.to_string())?;
    let body = body.map(|b| b.to_string()).unwrap_or_default();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .map_err(|e| e.to_string())?;
    let mut reader = BufReader::new(s);
    let mut status = String::new();
    reader.read_line(&mut status).map_err(|e| e.to_string())?;
    let mut length = None;
    loop {
        let mut line = String::new();
        reader.read_line(&mut line).map_err(|e| e.to_string())?;
        if line.trim().is_empty() {
            break;
        }
        if let Some((n, v)) = line.split_once(':') {
            if n.eq_ignore_ascii_case("content-length") {
                length = v.trim().parse::<usize>().ok();
            }
        }
    }
    let mut bytes = Vec::new();
    match length {
        Some(n) => {
            bytes.resize(n, 0);
            reader.read_exact(&mut bytes).map_err(|e| e.to_string())?;
        }
        None => {
            reader.read_to_end(&mut bytes).map_err(|e| e.to_string())?;
        }
    }
    let v: Value = serde_json::from_slice(&bytes).map_err(|e| format!("{e}: {status}"))?;
    if !status.contains(" 200") {
        return Err(format!("{method} {path}: {status}: {}", v["value"]));
    }
    Ok(v["value"].clone())
}

/// chromedriver and one browser session, ended when dropped.
struct Browser {
    driver: Child,
    port: u16,
    session: String,
    _profile: tempfile::TempDir,
}

impl Browser {
    fn start() -> Browser {
        assert!(
            Path::new(CHROMEDRIVER).exists() && Path::new(CHROMIUM).exists(),
            "{CHROMEDRIVER} or {CHROMIUM} is missing: run tools/setup.sh (it installs Debian's chromium and chromium-driver; CI has them)"
        );
        let port = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().port()
        };
        let driver = Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromedriver starts");
        let profile = tempfile::tempdir().unwrap();
        let mut b = Browser {
            driver,
            port,
            session: String::new(),
            _profile: profile,
        };
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(v) = http(port, "GET", "/status", None) {
                if v["ready"] == true {
                    break;
                }
            }
            assert!(Instant::now() < deadline, "chromedriver did not start");
            std::thread::sleep(Duration::from_millis(100));
        }
        let args = [
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-dev-shm-usage",
            "--window-size=1100,700",
        ]
        .iter()
        .map(|s| s.to_string())
        .chain([format!("--user-data-dir={}", b._profile.path().display())])
        .collect::<Vec<_>>();
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {"binary": CHROMIUM, "args": args}
        }}});
        let v = http(port, "POST", "/session", Some(&caps)).expect("a browser session");
        b.session = v["sessionId"].as_str().expect("a session id").to_string();
        b
    }

    fn call(&self, method: &str, path: &str, body: Option<Value>) -> Value {
        let p = format!("/session/{}{path}", self.session);
        http(self.port, method, &p, body.as_ref()).unwrap_or_else(|e| panic!("{e}"))
    }

    fn js(&self, script: &str) -> Value {
        self.call(
            "POST",
            "/execute/sync",
            Some(json!({"script": script, "args": []})),
        )
    }

    /// The page's state.
    fn state(&self) -> Value {
        self.js("const V = window.verisplatViewer; if (!V) return null; \
             return {camera: V.camera, settings: V.settings, frames: V.frames, \
             fullFrames: V.fullFrames, lastSeq: V.lastSeq, errors: V.errors, \
             cameraIndex: V.cameraIndex, connected: V.connected, focus: V.focus, \
             screenshots: V.screenshots, keyframes: V.keyframes.length, \
             lastExport: V.lastExport, turntable: V.turntable, pathFrames: V.pathFrames, \
             histLabel: document.getElementById('hist-label').textContent, \
             upFlipped: V.upFlipped, \
             banner: document.getElementById('banner').hidden ? null : document.getElementById('banner').textContent, \
             readout: document.getElementById('readout').textContent, \
             helloGaussians: V.hello && V.hello.gaussians, \
             lastFrameGaussians: V.lastFrame && V.lastFrame.gaussians, \
             hello: V.hello && {cameras: V.hello.cameras, size: V.hello.size}};")
    }

    /// Polls the page's state until `ok` holds (or panics after `within`).
    fn wait(&self, what: &str, within: Duration, ok: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + within;
        loop {
            let s = self.state();
            if !s.is_null() && ok(&s) {
                return s;
            }
            assert!(Instant::now() < deadline, "{what}: page state {s}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn element(&self, css: &str) -> String {
        let v = self.call(
            "POST",
            "/element",
            Some(json!({"using": "css selector", "value": css})),
        );
        v.as_object()
            .and_then(|o| o.values().next())
            .and_then(Value::as_str)
            .unwrap_or_else(|| panic!("no element {css}"))
            .to_string()
    }

    fn actions(&self, actions: Value) {
        self.call("POST", "/actions", Some(json!({ "actions": actions })));
        self.call("DELETE", "/actions", None);
    }

    /// Drags with button `button` from the centre of the element `css` by (dx, dy).
    fn drag(&self, css: &str, dx: i64, dy: i64, button: u8) {
        let centre = self.js(&format!(
            "const r = document.querySelector('{css}').getBoundingClientRect(); \
             return [Math.round(r.left + r.width / 2), Math.round(r.top + r.height / 2)];"
        ));
        let (x, y) = (centre[0].as_i64().unwrap(), centre[1].as_i64().unwrap());
        self.actions(json!([{
            "type": "pointer", "id": "mouse", "parameters": {"pointerType": "mouse"},
            "actions": [
                {"type": "pointerMove", "origin": "viewport", "x": x, "y": y, "duration": 0},
                {"type": "pointerDown", "button": button},
                {"type": "pointerMove", "origin": "pointer", "x": dx / 2, "y": dy / 2, "duration": 150},
                {"type": "pointerMove", "origin": "pointer", "x": dx - dx / 2, "y": dy - dy / 2, "duration": 150},
                {"type": "pointerUp", "button": button}
            ]
        }]));
    }

    fn hold_key(&self, key: &str, ms: u64) {
        self.actions(json!([{
            "type": "key", "id": "keyboard",
            "actions": [
                {"type": "keyDown", "value": key},
                {"type": "pause", "duration": ms},
                {"type": "keyUp", "value": key}
            ]
        }]));
    }

    fn screenshot_png(&self) -> Vec<u8> {
        let b64 = self.call("GET", "/screenshot", None);
        base64_decode(b64.as_str().expect("base64 text"))
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = http(
                self.port,
                "DELETE",
                &format!("/session/{}", self.session),
                None,
            );
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

fn base64_decode(s: &str) -> Vec<u8> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let digits: Vec<u32> = s.bytes().filter_map(value).collect();
    let mut out = Vec::with_capacity(digits.len() * 3 / 4);
    for chunk in digits.chunks(4) {
        let mut n = 0u32;
        for (i, d) in chunk.iter().enumerate() {
            n |= d << (18 - 6 * i);
        }
        let bytes = [(n >> 16) as u8, (n >> 8) as u8, n as u8];
        out.extend_from_slice(&bytes[..chunk.len().saturating_sub(1)]);
    }
    out
}

fn vec3(v: &Value) -> [f64; 3] {
    [0, 1, 2].map(|i| v[i].as_f64().unwrap_or(f64::NAN))
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn len(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Column `k` of a cameras.json rotation (right, down, forward).
fn axis(cam: &Value, k: usize) -> [f64; 3] {
    [0, 1, 2].map(|r| cam["rotation"][r][k].as_f64().unwrap_or(f64::NAN))
}

#[test]
fn the_page_drives_the_viewer_in_headless_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = std::env::var("VERISPLAT_VIEWER_SCENE").ok();
    let scene_args: Vec<&str> = match &scene {
        Some(s) => vec![s.as_str()],
        None => vec!["--demo"],
    };
    let mut render = vec!["render"];
    render.extend(&scene_args);
    render.extend([
        "--cpu",
        "--quiet",
        "--orbit",
        "3",
        "--width",
        "160",
        "--height",
        "120",
        "--export-cameras",
        "cams.json",
        "-o",
        "orbit/f_{}.png",
    ]);
    // VERISPLAT_VIEWER_LENS=SPEC: the cameras (and so the viewer) through that lens.
    let lens = std::env::var("VERISPLAT_VIEWER_LENS").ok();
    if let Some(spec) = &lens {
        render.extend(["--lens", spec.as_str()]);
    }
    verisplat_ok(d, &render);
    let mut args = scene_args.clone();
    let max_resolution =
        std::env::var("VERISPLAT_VIEWER_MAX_RESOLUTION").unwrap_or_else(|_| "640x400".into());
    // The Vulkan pipeline (lavapipe in CI), as `verisplat view` runs by default.
    args.extend([
        "--cameras",
        "cams.json",
        "--max-resolution",
        &max_resolution,
    ]);
    let mut viewer = Viewer::start(d, &args);
    let browser = Browser::start();
    browser.call("POST", "/url", Some(json!({"url": viewer.url})));
    let first = browser.wait("first full frame", Duration::from_secs(90), |s| {
        s["connected"] == true && s["fullFrames"].as_u64() > Some(0)
    });
    assert_eq!(first["cameraIndex"], 0, "starts at the first camera");
    let size = first["hello"]["size"].as_f64().unwrap();

    let s = orbit_and_fly(&browser, &first, size);
    let before = drag_the_sliders(&browser, &s);
    select_a_camera_from_the_list(&browser, &before, &first, size);
    turntable_and_flip(&browser);
    export_keyframes_and_preview_them(&browser, d, &scene_args);
    error_banner_and_a_clean_log(&browser, &mut viewer);
    page_screenshot_shows_a_picture(&browser);
}

/// Orbiting with a left drag and flying forward with W; returns the state after the flight.
fn orbit_and_fly(browser: &Browser, first: &Value, size: f64) -> Value {
    // Left drag orbits: the camera moves, its distance to the focus stays.
    let before = first["camera"].clone();
    let focus = vec3(&first["focus"]);
    browser.drag("#view", 160, 0, 0);
    let s = browser.wait("orbit", Duration::from_secs(60), |s| {
        s["camera"]["position"] != before["position"]
            && s["frames"].as_u64() > first["frames"].as_u64()
    });
    let (p0, p1) = (vec3(&before["position"]), vec3(&s["camera"]["position"]));
    let (r0, r1) = (len(sub(p0, focus)), len(sub(p1, vec3(&s["focus"]))));
    assert!((r0 - r1).abs() < 1e-3 * r0, "orbit radius {r0} -> {r1}");
    assert!(
        len(sub(p0, p1)) > 0.05 * r0,
        "orbit moved {}",
        len(sub(p0, p1))
    );
    // Still looking at the focus.
    let fwd = axis(&s["camera"], 2);
    let to_focus = sub(vec3(&s["focus"]), p1);
    assert!(dot(fwd, to_focus) / len(to_focus) > 0.999);

    // W flies forward along the view direction.
    let before = s.clone();
    browser.hold_key("w", 500);
    let s = browser.wait("fly", Duration::from_secs(60), |s| {
        s["camera"]["position"] != before["camera"]["position"]
            && s["lastSeq"].as_u64() > before["lastSeq"].as_u64()
    });
    let moved = sub(
        vec3(&s["camera"]["position"]),
        vec3(&before["camera"]["position"]),
    );
    let fwd = axis(&before["camera"], 2);
    assert!(
        dot(moved, fwd) > 0.05 * size,
        "W moved {moved:?} along {fwd:?}"
    );
    assert!(
        dot(moved, fwd) > 0.99 * len(moved),
        "W moved sideways: {moved:?}"
    );
    assert_eq!(
        s["camera"]["rotation"], before["camera"]["rotation"],
        "W turned the camera"
    );
    s
}

/// The scale and max-scale sliders; returns the state with the max-scale filter off.
fn drag_the_sliders(browser: &Browser, s: &Value) -> Value {
    // The scale slider, dragged left, lowers the splat scale factor.
    let before = s.clone();
    browser.drag("#scale", -60, 0, 0);
    let s = browser.wait("scale slider", Duration::from_secs(60), |s| {
        s["settings"]["scale_modifier"].as_f64() < Some(0.9)
            && s["lastSeq"].as_u64() > before["lastSeq"].as_u64()
    });
    assert_eq!(s["camera"], before["camera"], "the slider moved the camera");
    // The slider is log-spaced about 1 at its centre (where the drags start): as far to
    // the right gives the reciprocal factor.
    let low = s["settings"]["scale_modifier"].as_f64().unwrap();
    browser.drag("#scale", 60, 0, 0);
    let s = browser.wait("scale slider right", Duration::from_secs(60), |s| {
        s["settings"]["scale_modifier"].as_f64() > Some(1.1)
    });
    let high = s["settings"]["scale_modifier"].as_f64().unwrap();
    assert!(
        (low * high - 1.0).abs() < 0.1,
        "scale {low} left, {high} right"
    );
    // A click at the centre is 1 again.
    browser.drag("#scale", 0, 0, 0);
    let before = browser.wait("scale slider centre", Duration::from_secs(60), |s| {
        s["settings"]["scale_modifier"].as_f64() == Some(1.0)
    });

    // The max-scale slider, pulled left, sets a threshold inside the scene's range and
    // the histogram label says how much is kept; back at the right end it is off.
    assert!(before["histLabel"].as_str().unwrap().contains("Gaussians"));
    browser.drag("#maxscale", -40, 0, 0);
    let s = browser.wait("max scale", Duration::from_secs(30), |s| {
        s["settings"]["max_scale"].is_number()
    });
    let label = s["histLabel"].as_str().unwrap();
    assert!(label.contains("% kept"), "{label}");
    browser.drag("#maxscale", 135, 0, 0);
    browser.wait("max scale off", Duration::from_secs(30), |s| {
        s["settings"]["max_scale"].is_null()
    })
}

/// Clicking a camera of the list snaps to it, and frames keep coming without errors.
fn select_a_camera_from_the_list(browser: &Browser, before: &Value, first: &Value, size: f64) {
    // Clicking camera 2 of the list snaps to its pose and field of view.
    let item = browser.element("#cameras li:nth-child(3)");
    browser.call("POST", &format!("/element/{item}/click"), Some(json!({})));
    let s = browser.wait("select camera", Duration::from_secs(60), |s| {
        s["cameraIndex"] == 2 && s["lastSeq"].as_u64() > before["lastSeq"].as_u64()
    });
    let want = &s["hello"]["cameras"][2]["camera"];
    let got = &s["camera"];
    assert!(len(sub(vec3(&got["position"]), vec3(&want["position"]))) < 1e-6 * size.max(1.0));
    for k in 0..3 {
        assert!(len(sub(axis(got, k), axis(want, k))) < 1e-6, "axis {k}");
    }
    let vfov = |c: &Value| (c["height"].as_f64().unwrap() / c["fy"].as_f64().unwrap()).atan();
    assert!((vfov(got) - vfov(want)).abs() < 1e-6);

    // Frames keep coming, and come back full after the moves; no error was shown.
    let s = browser.wait("frames after the moves", Duration::from_secs(60), |s| {
        s["frames"].as_u64() > before["frames"].as_u64()
    });
    std::thread::sleep(Duration::from_millis(1500));
    let end = browser.state();
    assert!(end["fullFrames"].as_u64() > first["fullFrames"].as_u64());
    assert_eq!(end["errors"], json!([]), "the page showed errors");
    assert!(s["frames"].as_u64() >= Some(4));
}

/// The turntable (T) and the "Flip up axis" button.
fn turntable_and_flip(browser: &Browser) {
    // Turntable: T starts the rotation about the focus, T stops it.
    browser.hold_key("t", 50);
    let spinning = browser.wait("turntable", Duration::from_secs(30), |s| {
        s["turntable"] == true
    });
    let moved = browser.wait("turntable moves", Duration::from_secs(30), |s| {
        s["camera"]["position"] != spinning["camera"]["position"]
    });
    browser.hold_key("t", 50);
    browser.wait("turntable stops", Duration::from_secs(30), |s| {
        s["turntable"] == false
    });
    let r0 = len(sub(
        vec3(&spinning["camera"]["position"]),
        vec3(&spinning["focus"]),
    ));
    let r1 = len(sub(
        vec3(&moved["camera"]["position"]),
        vec3(&moved["focus"]),
    ));
    assert!((r0 - r1).abs() < 1e-3 * r0, "turntable radius {r0} -> {r1}");

    // "Flip up axis" turns the view about its axis: the camera's down axis, along world
    // +y (up is -y), points along -y after the flip, and back after a second click.
    let down_y = |s: &Value| axis(&s["camera"], 1)[1];
    let flip = browser.element("#flip-up");
    let before = browser.state();
    assert!(down_y(&before) > 0.0, "{}", before["camera"]);
    browser.call("POST", &format!("/element/{flip}/click"), Some(json!({})));
    let flipped = browser.wait("flip", Duration::from_secs(30), |s| {
        s["upFlipped"] == true && s["lastSeq"].as_u64() > before["lastSeq"].as_u64()
    });
    assert!(down_y(&flipped) < 0.0, "{}", flipped["camera"]);
    browser.call("POST", &format!("/element/{flip}/click"), Some(json!({})));
    let back = browser.wait("unflip", Duration::from_secs(30), |s| {
        s["upFlipped"] == false
    });
    assert!(down_y(&back) > 0.0);
}

/// Keyframes added, exported (and rendered by `render --cameras`) and previewed, and the
/// screenshot button.
fn export_keyframes_and_preview_them(browser: &Browser, d: &Path, scene_args: &[&str]) {
    // Three keyframes (camera 0, 1, 2 by N), exported as the keyframe JSON render reads.
    browser.hold_key("n", 30); // camera 0 (after 2, wrapping)
    let add = browser.element("#kf-add");
    for k in 0..3 {
        browser.wait("camera step", Duration::from_secs(30), |s| {
            s["cameraIndex"] == k
        });
        browser.call("POST", &format!("/element/{add}/click"), Some(json!({})));
        browser.wait("keyframe added", Duration::from_secs(30), |s| {
            s["keyframes"] == k + 1
        });
        browser.hold_key("n", 30);
    }
    let export = browser.element("#kf-export");
    browser.call("POST", &format!("/element/{export}/click"), Some(json!({})));
    let s = browser.wait("export", Duration::from_secs(30), |s| {
        !s["lastExport"].is_null()
    });
    let text = s["lastExport"]["text"].as_str().expect("exported text");
    let path: Value = serde_json::from_str(text).expect("the export is JSON");
    assert_eq!(
        path["keyframes"].as_array().map(Vec::len),
        Some(3),
        "{text}"
    );
    std::fs::write(d.join("keyframes.json"), text).unwrap();
    let mut render = vec!["render"];
    render.extend(scene_args);
    render.extend([
        "--cpu",
        "--quiet",
        "--cameras",
        "keyframes.json",
        "--scale",
        "0.1",
        "--frames",
        "0",
        "-o",
        "kf.png",
    ]);
    verisplat_ok(d, &render);

    // Preview plays the path the server sampled: 3 keys 2 s apart at 30 frames/s, 121 frames.
    let preview = browser.element("#kf-preview");
    let before = browser.state();
    browser.call(
        "POST",
        &format!("/element/{preview}/click"),
        Some(json!({})),
    );
    let playing = browser.wait("preview", Duration::from_secs(30), |s| {
        s["pathFrames"] == 121
    });
    browser.wait("preview moves", Duration::from_secs(30), |s| {
        s["camera"]["position"] != playing["camera"]["position"]
            && s["lastSeq"].as_u64() > before["lastSeq"].as_u64()
    });
    browser.call(
        "POST",
        &format!("/element/{preview}/click"),
        Some(json!({})),
    );

    // The screenshot button downloads a file of the view.
    let shot = browser.element("#shot-png");
    browser.call("POST", &format!("/element/{shot}/click"), Some(json!({})));
    browser.wait("screenshot", Duration::from_secs(60), |s| {
        s["screenshots"] == 1
    });
}

/// A server error in the banner, dismissed; the viewer lives on and the validation layer
/// found nothing.
fn error_banner_and_a_clean_log(browser: &Browser, viewer: &mut Viewer) {
    // A server error appears in the page's banner.
    browser.js("window.verisplatViewer.send({type: 'dance'}); return null;");
    let s = browser.wait("error banner", Duration::from_secs(30), |s| {
        !s["banner"].is_null()
    });
    assert!(
        s["banner"].as_str().unwrap().contains("dance"),
        "{}",
        s["banner"]
    );
    // Dismissed by a click, as before the screenshot of the page below.
    browser.js("document.getElementById('banner').click(); return null;");
    browser.wait("banner closed", Duration::from_secs(10), |s| {
        s["banner"].is_null()
    });
    // (The state before the key: the snap's frame may arrive before the next poll.)
    let before = browser.state();
    browser.hold_key("p", 30);
    browser.wait("a frame of camera 2 again", Duration::from_secs(60), |s| {
        s["cameraIndex"] == 2 && s["lastSeq"].as_u64() > before["lastSeq"].as_u64()
    });
    std::thread::sleep(Duration::from_millis(1500));
    let end = browser.state();
    assert_eq!(
        end["errors"].as_array().map(Vec::len),
        Some(1),
        "{}",
        end["errors"]
    );
    assert!(viewer.alive());
    // The validation layer (on through common::cli) found nothing in the GPU viewer.
    let log: Vec<String> = viewer.stderr.try_iter().collect();
    assert!(!log.iter().any(|l| l.contains("[vulkan")), "{log:?}");
}

/// The page screenshot shows a picture in the canvas area.
fn page_screenshot_shows_a_picture(browser: &Browser) {
    // The page screenshot shows a picture in the canvas area (left of the panel).
    browser.js("document.getElementById('panel').scrollTop = 0; return null;");
    let png = browser.screenshot_png();
    if let Ok(path) = std::env::var("VERISPLAT_VIEWER_SCREENSHOT") {
        std::fs::write(&path, &png).unwrap();
    }
    let img = image::load_from_memory(&png).expect("a PNG").to_rgb8();
    let (w, h) = img.dimensions();
    let mut sum = 0.0;
    let mut sum2 = 0.0;
    let mut n = 0.0;
    for y in (h / 3)..(h * 9 / 10) {
        for x in (w / 4)..(w.saturating_sub(300)) {
            let p = img.get_pixel(x, y).0;
            let l = (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0;
            sum += l;
            sum2 += l * l;
            n += 1.0;
        }
    }
    let mean = sum / n;
    let var = sum2 / n - mean * mean;
    assert!(
        var > 100.0 && mean > 5.0,
        "blank canvas: mean {mean}, variance {var}"
    );
}

/// Opens `viewer` in a new browser and waits for its first full frame.
fn open(viewer: &Viewer) -> (Browser, Value) {
    let browser = Browser::start();
    browser.call("POST", "/url", Some(json!({"url": viewer.url})));
    let first = browser.wait("first full frame", Duration::from_secs(90), |s| {
        s["connected"] == true && s["fullFrames"].as_u64() > Some(0)
    });
    (browser, first)
}

/// Types `text` over the value of the input `css` (as after selecting it all), then
/// clicks `then`, which takes the focus (the input's change event).
fn type_into(browser: &Browser, css: &str, text: &str, then: &str) {
    let input = browser.element(css);
    // Emptied without an event, as typing over a selection does.
    browser.js(&format!(
        "document.querySelector('{css}').value = ''; return null;"
    ));
    browser.call(
        "POST",
        &format!("/element/{input}/value"),
        Some(json!({ "text": text })),
    );
    let other = browser.element(then);
    browser.call("POST", &format!("/element/{other}/click"), Some(json!({})));
}

/// The viewer of the demo scene (frames at most 640x400) in a browser, at its first
/// full frame.
fn demo_page() -> (tempfile::TempDir, Viewer, Browser, Value) {
    let dir = tempfile::tempdir().unwrap();
    let viewer = Viewer::start(dir.path(), &["--demo", "--max-resolution", "640x400"]);
    let (browser, first) = open(&viewer);
    (dir, viewer, browser, first)
}

/// The canvas is the area left of the side panel (no rendered pixel hidden behind it, the
/// subject in the middle of what is seen), and the whole window with the panel hidden
/// (issue 29, item 4).
#[test]
fn the_canvas_is_the_area_beside_the_panel() {
    let (_dir, _viewer, browser, first) = demo_page();
    // The canvas ends where the panel starts; the frame is the canvas's size.
    let geometry = || {
        browser.js(
            "const c = document.getElementById('view').getBoundingClientRect(); \
             const p = document.getElementById('panel').getBoundingClientRect(); \
             const v = document.getElementById('view'); \
             return {right: c.right, left: c.left, panelLeft: p.left, window: window.innerWidth, \
                     width: v.width, dpr: window.devicePixelRatio, camera: window.verisplatViewer.camera.width};",
        )
    };
    let g = geometry();
    let f = |k: &str| g[k].as_f64().unwrap();
    assert_eq!(f("left"), 0.0, "{g}");
    assert!(
        (f("right") - f("panelLeft")).abs() <= 1.0,
        "the canvas reaches under the panel: {g}"
    );
    assert!(f("panelLeft") < f("window") - 200.0, "{g}");
    assert_eq!(f("camera"), f("width"), "{g}");
    assert_eq!(f("width"), (f("right") * f("dpr")).round(), "{g}");
    let frame_before = first["frames"].as_u64().unwrap();
    // Hidden panel: the canvas takes the window, and a frame of that width follows.
    let toggle = browser.element("#panel-toggle");
    browser.call("POST", &format!("/element/{toggle}/click"), Some(json!({})));
    let wide = browser.wait("wide canvas", Duration::from_secs(30), |s| {
        s["camera"]["width"].as_f64() == Some((f("window") * f("dpr")).round())
            && s["frames"].as_u64() > Some(frame_before)
    });
    assert!(wide["camera"]["width"].as_f64() > g["camera"].as_f64());
    browser.call("POST", &format!("/element/{toggle}/click"), Some(json!({})));
    browser.wait("narrow canvas again", Duration::from_secs(30), |s| {
        s["camera"]["width"].as_f64() == g["camera"].as_f64()
    });
}

/// Once frames stop, the readout says the view is at rest instead of the last moving
/// frames/s (issue 29, item 2).
#[test]
fn the_readout_says_at_rest() {
    let (_dir, _viewer, browser, _) = demo_page();
    let rest = browser.wait("at rest", Duration::from_secs(30), |s| {
        s["readout"]
            .as_str()
            .is_some_and(|r| r.starts_with("at rest"))
    });
    assert!(
        rest["readout"].as_str().unwrap().contains("full"),
        "{}",
        rest["readout"]
    );
}

/// The keyframe inputs refuse values outside their range visibly: "Seconds apart" 0
/// becomes 0.1 (its minimum, not a silent 1 s) with a banner saying so; the keyframes
/// are 0.1 s apart (issue 29, item 7).
#[test]
fn keyframe_inputs_refuse_values_out_of_range_visibly() {
    let (_dir, _viewer, browser, _) = demo_page();
    type_into(&browser, "#kf-spacing", "0", "#kf-add");
    let s = browser.wait("spacing refused", Duration::from_secs(10), |s| {
        s["keyframes"] == 1 && !s["banner"].is_null()
    });
    let banner = s["banner"].as_str().unwrap();
    assert!(
        banner.contains("Seconds apart") && banner.contains("0.1"),
        "{banner}"
    );
    let value = |css: &str| browser.js(&format!("return document.querySelector('{css}').value;"));
    assert_eq!(value("#kf-spacing"), "0.1");
    let add = browser.element("#kf-add");
    browser.call("POST", &format!("/element/{add}/click"), Some(json!({})));
    browser.wait("second keyframe", Duration::from_secs(10), |s| {
        s["keyframes"] == 2
    });
    let labels = browser.js(
        "return [...document.querySelectorAll('#keyframes li span')].map((e) => e.textContent);",
    );
    assert_eq!(labels, json!(["t = 0.0 s", "t = 0.1 s"]));
    // Frames/s: 0 and text are refused the same way.
    type_into(&browser, "#kf-fps", "0", "#kf-add");
    browser.wait("fps refused", Duration::from_secs(10), |s| {
        s["errors"].as_array().is_some_and(|e| {
            e.iter()
                .any(|m| m.as_str().unwrap_or("").contains("Frames/s"))
        })
    });
    assert_eq!(value("#kf-fps"), "1");
}

/// A message over the server's limit closes the connection with 1009 and the reason,
/// and the page shows it (then reconnects) instead of only "disconnected" (issue 29,
/// item 5).
#[test]
fn the_page_shows_why_the_server_closed_the_connection() {
    let (_dir, mut viewer, browser, _) = demo_page();
    browser
        .js("window.verisplatViewer.send({type: 'rest', pad: 'x'.repeat(20 << 20)}); return null;");
    let s = browser.wait("close reason", Duration::from_secs(30), |s| {
        s["banner"].as_str().is_some_and(|b| b.contains("too big"))
    });
    let banner = s["banner"].as_str().unwrap();
    assert!(
        banner.contains("over the limit of 4.0 MiB") && banner.contains("1009"),
        "{banner}"
    );
    let before = browser.state();
    browser.wait("reconnected", Duration::from_secs(30), |s| {
        s["connected"] == true && s["frames"].as_u64() > before["frames"].as_u64()
    });
    assert!(viewer.alive());
}

/// The server restarted on the same port with another scene: the open page sets itself
/// up from the new scene's description (camera list, Gaussians, histogram, SH range, the
/// view at its first camera), as a fresh page would (issue 29, item 1).
#[test]
fn a_restarted_server_with_another_scene_sets_the_page_up_anew() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    verisplat_ok(
        d,
        &[
            "render",
            "--demo",
            "--cpu",
            "--quiet",
            "--orbit",
            "3",
            "--width",
            "160",
            "--height",
            "120",
            "--export-cameras",
            "cams.json",
            "-o",
            "orbit/f_{}.png",
        ],
    );
    verisplat_ok(
        d,
        &[
            "gen",
            "5000",
            "--seed",
            "7",
            "--sh-degree",
            "0",
            "-o",
            "other.ply",
        ],
    );
    let args = [
        "--cameras",
        "cams.json",
        "--max-resolution",
        "640x400",
        "--demo",
    ];
    let viewer = Viewer::start(d, &args);
    let port = viewer.port;
    let (browser, first) = open(&viewer);
    assert_eq!(first["hello"]["cameras"].as_array().map(Vec::len), Some(3));
    let dom = || {
        browser.js(
            "return {cameras: document.querySelectorAll('#cameras li').length, \
             shMax: document.getElementById('sh').max, shValue: document.getElementById('sh').value, \
             shOut: document.getElementById('sh-out').textContent, \
             hist: document.getElementById('hist-label').textContent, \
             bars: document.querySelectorAll('#hist div').length, \
             scene: document.getElementById('scene-name').textContent, \
             readout: document.getElementById('readout').textContent, \
             lastGaussians: window.verisplatViewer.lastFrame && window.verisplatViewer.lastFrame.gaussians, \
             histBins: window.verisplatViewer.hello.max_scale_histogram.counts.length};",
        )
    };
    let old = dom();
    assert_eq!(old["cameras"], 3);
    assert_eq!(old["shMax"], "2");
    assert!(
        old["hist"].as_str().unwrap().contains("1,873 Gaussians"),
        "{old}"
    );

    drop(viewer);
    let other = Viewer::start_at(d, &["other.ply", "--max-resolution", "640x400"], &[], port);
    let s = browser.wait("the new scene", Duration::from_secs(60), |s| {
        s["connected"] == true && s["helloGaussians"] == 5000 && s["lastFrameGaussians"] == 5000
    });
    let new = dom();
    assert_eq!(new["cameras"], 1, "{new}");
    assert_eq!(new["shMax"], "0", "{new}");
    assert_eq!(new["shValue"], "0", "{new}");
    assert_eq!(new["shOut"], "0", "{new}");
    assert!(
        new["hist"].as_str().unwrap().contains("5,000 Gaussians"),
        "{new}"
    );
    assert_eq!(new["bars"], new["histBins"], "{new}");
    assert_eq!(new["scene"], "other.ply", "{new}");
    assert!(
        new["readout"].as_str().unwrap().contains("of 5,000"),
        "{new}"
    );
    assert_eq!(s["cameraIndex"], 0);
    assert!(s["settings"]["sh_degree"].is_null() && s["settings"]["max_scale"].is_null());
    // At the new scene's first camera, which its list shows.
    let want = &s["hello"]["cameras"][0]["camera"];
    let got = &s["camera"];
    assert!(len(sub(vec3(&got["position"]), vec3(&want["position"]))) < 1e-4);
    // The page said so, and nothing it sent was refused (no settings of the old scene).
    let banner = s["banner"].as_str().unwrap_or("");
    assert!(banner.contains("other.ply"), "{banner}");
    let errors: Vec<&str> = s["errors"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    assert!(
        errors.iter().all(|e| e.contains("reconnecting")),
        "{errors:?}"
    );
    // Clicking its one camera stays on it.
    let item = browser.element("#cameras li:nth-child(1)");
    browser.call("POST", &format!("/element/{item}/click"), Some(json!({})));
    let s = browser.wait("camera 0", Duration::from_secs(30), |s| {
        s["cameraIndex"] == 0
    });
    assert!(len(sub(vec3(&s["camera"]["position"]), vec3(&want["position"]))) < 1e-4);
    drop(other);
}
