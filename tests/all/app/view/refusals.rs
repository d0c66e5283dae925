//! Refusals: bad messages, render errors, bad HTTP requests and oversized WebSocket
//! messages are answered with an error or a reason to their sender while the server and
//! the other tabs go on.

use super::{cameras, WAIT};
use crate::common::viewer::{diff, Client, Incoming, Viewer};
use serde_json::{json, Value};
use std::time::Duration;

/// Waits for an error message (skipping frames); returns its text.
fn error(c: &mut Client, what: &str) -> String {
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match c.next(left) {
            Some(Incoming::Text(v)) if v["type"] == "error" => {
                return v["message"].as_str().unwrap_or("").to_string()
            }
            Some(_) => {}
            None => panic!("{what}: no error message"),
        }
    }
}

#[test]
fn bad_messages_are_refused_and_other_tabs_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    cameras(d);
    let mut viewer = Viewer::start(d, &["--demo", "--cpu", "--cameras", "cams.json"]);
    let mut bad = viewer.connect();
    let mut good = viewer.connect();
    let cam = good.camera(0);
    let first = {
        let seq = good.send(json!({"type": "view", "camera": cam}));
        good.frame(seq, true, WAIT).rgb()
    };
    // The good tab's frames stay the same whatever the other tab does (its own
    // settings, too).
    let good_frame = |good: &mut Client, what: &str| {
        let seq = good.send(json!({"type": "view", "camera": cam}));
        let f = good.frame(seq, true, WAIT);
        assert_eq!(diff(&f.rgb(), &first), (0, 0), "after {what}");
    };
    bad.send(json!({"type": "settings", "settings": {"mode": "depth", "scale_modifier": 2.0}}));
    good_frame(&mut good, "the other tab's settings");

    let entry = bad.camera(0);
    let with = |field: &str, v: Value| {
        let mut e = entry.clone();
        e[field] = v;
        json!({"type": "view", "camera": e}).to_string()
    };
    let cases: Vec<(&str, String, &str)> = vec![
        ("malformed JSON", "{\"type\": \"view\", ".into(), "not understood"),
        ("unknown type", r#"{"type": "dance", "seq": 3}"#.into(), "dance"),
        ("no type", r#"{"seq": 3}"#.into(), "not understood"),
        ("NaN position (null)", with("position", json!([null, 0, 0])), "camera refused"),
        ("infinite position", with("position", json!([0, 0, 0])).replace("[0,0,0]", "[1e999,0,0]"), "not understood"),
        ("NaN rotation", with("rotation", json!([[null, 0, 0], [0, 1, 0], [0, 0, 1]])), "camera refused"),
        ("0x0 canvas", with("width", json!(0)).replace("\"height\":64", "\"height\":0"), "resolution"),
        ("100000x100000 canvas", with("width", json!(100000)).replace("\"height\":64", "\"height\":100000"), "resolution"),
        ("negative focal length", with("fx", json!(-5)), "camera refused"),
        ("not a rotation", with("rotation", json!([[2, 0, 0], [0, 2, 0], [0, 0, 2]])), "rotation"),
        ("scale modifier 0", json!({"type": "settings", "settings": {"scale_modifier": 0}}).to_string(), "scale_modifier"),
        ("min opacity 2", json!({"type": "settings", "settings": {"min_opacity": 2}}).to_string(), "min_opacity"),
        ("SH degree 7", json!({"type": "settings", "settings": {"sh_degree": 7}}).to_string(), "sh_degree"),
        ("background 2", json!({"type": "settings", "settings": {"background": [2, 0, 0]}}).to_string(), "background"),
        ("max scale -1", json!({"type": "settings", "settings": {"max_scale": -1}}).to_string(), "max_scale"),
        ("unknown mode", json!({"type": "settings", "settings": {"mode": "x-ray"}}).to_string(), "not understood"),
        ("rest before a view", json!({"type": "rest"}).to_string(), "rest before any view"),
        ("camera index 99", json!({"type": "select_camera", "index": 99}).to_string(), "camera 99 does not exist"),
        ("no keyframes", json!({"type": "export_keyframes", "format": "verisplat", "fps": 30, "keyframes": []}).to_string(), "no keyframes"),
        ("keyframe fps 0", json!({"type": "export_keyframes", "format": "verisplat", "fps": 0, "keyframes": [{"time": 0, "camera": entry}]}).to_string(), "fps"),
        ("wrong field type", json!({"type": "select_camera", "index": "one"}).to_string(), "not understood"),
    ];
    for (what, text, needle) in &cases {
        bad.send_raw(text);
        let e = error(&mut bad, what);
        assert!(e.contains(needle), "{what}: error {e:?} lacks {needle:?}");
        assert!(viewer.alive(), "{what} stopped the server");
        good_frame(&mut good, what);
    }
    // A binary message.
    bad.ws
        .send(tungstenite::Message::binary(vec![1u8, 2, 3]))
        .unwrap();
    assert!(error(&mut bad, "binary").contains("binary"));

    // The bad tab itself still works after all of that.
    let seq = bad.send(json!({"type": "view", "camera": entry}));
    bad.frame(seq, true, WAIT);

    // A flood: thousands of messages at once are cut off with one error; the newest
    // accepted request still gets its frame, the other tab is served meanwhile.
    let mut last = 0;
    for _ in 0..3000 {
        last = bad.send(json!({"type": "view", "camera": entry, "interactive": true}));
    }
    let e = error(&mut bad, "flood");
    assert!(e.contains("too many messages"), "{e}");
    good_frame(&mut good, "flood");
    std::thread::sleep(Duration::from_millis(1100));
    let seq = bad.send(json!({"type": "view", "camera": entry}));
    assert!(seq > last);
    bad.frame(seq, true, WAIT);
    assert!(viewer.alive());

    // An oversized message closes only that connection.
    let huge = format!("{{\"type\":\"rest\",\"pad\":\"{}\"}}", "x".repeat(5 << 20));
    let _ = bad.ws.send(tungstenite::Message::text(huge));
    good_frame(&mut good, "an oversized message");
    assert!(viewer.alive());
}

/// A frame the renderer cannot make (here: more device memory than the budget) is an
/// error for the tab that asked; the renderer and the other tabs go on.
#[test]
fn render_errors_go_to_the_tab_that_asked() {
    let dir = tempfile::tempdir().unwrap();
    let mut viewer = Viewer::start_with_env(
        dir.path(),
        &["--demo", "--width", "96", "--max-resolution", "8000x8000"],
        &[("VERISPLAT_MEMORY_LIMIT", "24M")],
    );
    let mut a = viewer.connect();
    let mut b = viewer.connect();
    let small = a.camera(0);
    let mut big = small.clone();
    for (k, f) in [("width", 6000.0), ("height", 3375.0)] {
        big[k] = (f as u64).into();
    }
    for k in ["fx", "fy"] {
        big[k] = (big[k].as_f64().unwrap() * 62.5).into();
    }
    let seq = a.send(json!({"type": "view", "camera": big}));
    let e = loop {
        match a.next(WAIT) {
            Some(Incoming::Text(v)) if v["type"] == "error" => break v,
            Some(_) => {}
            None => panic!("no error for the oversized frame"),
        }
    };
    assert_eq!(e["seq"], seq);
    let message = e["message"].as_str().unwrap();
    assert!(message.contains("out of device memory"), "{message}");
    assert!(viewer.alive());
    for c in [&mut b, &mut a] {
        let seq = c.send(json!({"type": "view", "camera": small}));
        assert_eq!(c.frame(seq, true, WAIT).header["width"], 96);
    }
}

/// What is not an HTTP request, a head over the limit and an oversized WebSocket message
/// are each answered with their status (400, 408, 431, 505) or close code (1009) and a
/// sentence saying why, not a silently closed or reset connection (issue 29, item 5).
#[test]
fn bad_requests_and_oversized_messages_are_answered_with_a_reason() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let viewer = Viewer::start(dir.path(), &["--demo", "--cpu", "--width", "32"]);
    // Sends `bytes` (then half-closes if `close`); the answer up to the server's close.
    let ask = |bytes: &[u8], close: bool| -> String {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", viewer.port)).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        s.write_all(bytes).unwrap();
        if close {
            s.shutdown(std::net::Shutdown::Write).unwrap();
        }
        let mut out = Vec::new();
        let _ = s.read_to_end(&mut out);
        String::from_utf8_lossy(&out).into_owned()
    };
    let garbage = ask(b"garbage\r\n\r\n", false);
    assert!(
        garbage.starts_with("HTTP/1.1 400 Bad Request\r\n"),
        "{garbage:?}"
    );
    assert!(garbage.contains("not an HTTP request line"), "{garbage}");
    // A TLS hello (https:// to the viewer) is refused at once, not after a time-out.
    let start = std::time::Instant::now();
    let tls = ask(&[0x16, 0x03, 0x01, 0x00, 0xa5, 0x01, 0x00], false);
    assert!(tls.starts_with("HTTP/1.1 400"), "{tls:?}");
    assert!(tls.contains("http://, not https://"), "{tls}");
    assert!(
        start.elapsed() < Duration::from_secs(3),
        "{:?}",
        start.elapsed()
    );
    // A head that ends early, and one that never ends.
    let early = ask(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n", true);
    assert!(early.starts_with("HTTP/1.1 400"), "{early:?}");
    let slow = ask(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n", false);
    assert!(slow.starts_with("HTTP/1.1 408"), "{slow:?}");
    let http2 = ask(b"GET / HTTP/2.0\r\nHost: 127.0.0.1\r\n\r\n", false);
    assert!(http2.starts_with("HTTP/1.1 505"), "{http2:?}");
    // A 20 KB header: 431, read in full by the client (no reset).
    let big = format!(
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: {}\r\n\r\n",
        "a".repeat(20_000)
    );
    let answer = ask(big.as_bytes(), false);
    assert!(
        answer.starts_with("HTTP/1.1 431 Request Header Fields Too Large\r\n"),
        "{answer:?}"
    );
    assert!(answer.contains("over 16 KiB"), "{answer}");

    // A 20 MB WebSocket message: closed with 1009 (message too big) and the limit.
    let mut c = viewer.connect();
    let huge = format!("{{\"type\":\"rest\",\"pad\":\"{}\"}}", "x".repeat(20 << 20));
    c.ws.send(tungstenite::Message::text(huge)).unwrap();
    let deadline = std::time::Instant::now() + WAIT;
    let close = loop {
        assert!(std::time::Instant::now() < deadline, "no close");
        match c.ws.read() {
            Ok(tungstenite::Message::Close(frame)) => break frame,
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("the connection ended without a close: {e}"),
        }
    };
    let close = close.expect("a close code");
    assert_eq!(
        close.code,
        tungstenite::protocol::frame::coding::CloseCode::Size
    );
    assert!(
        close
            .reason
            .contains("20.0 MiB is over the limit of 4.0 MiB"),
        "{}",
        close.reason
    );
    // The server goes on.
    let mut c = viewer.connect();
    let seq = c.send(json!({"type": "view", "camera": c.camera(0)}));
    c.frame(seq, true, WAIT);
}
