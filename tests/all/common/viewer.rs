//! Helpers of the viewer tests: a `verisplat view` process on a free loopback port and a
//! WebSocket client with deadlines on every wait. The binary runs through
//! `common::cli` (validation layer on).
#![allow(dead_code)]

use super::cli;
use serde_json::Value;
use std::io::{BufRead, BufReader, ErrorKind};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

/// Runs `verisplat` to completion; panics with its stderr on failure.
pub fn verisplat_ok(dir: &Path, args: &[&str]) -> Output {
    let o = cli::verisplat_in(dir, args);
    assert!(
        o.status.success(),
        "verisplat {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// A running `verisplat view`, killed when dropped.
pub struct Viewer {
    pub child: Child,
    /// `http://127.0.0.1:PORT/`
    pub url: String,
    pub port: u16,
    /// What the process wrote to stderr so far (collected in the background).
    pub stderr: mpsc::Receiver<String>,
}

impl Viewer {
    /// Starts `verisplat view ARGS --port 0` in `dir` and waits (60 s at most) for the URL.
    pub fn start(dir: &Path, args: &[&str]) -> Viewer {
        Self::start_with_env(dir, args, &[])
    }

    /// As [`Viewer::start`] with environment variables (`VERISPLAT_VALIDATE=1`).
    pub fn start_with_env(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> Viewer {
        Self::start_at(dir, args, env, 0)
    }

    /// As [`Viewer::start_with_env`] on `port` (0: a free one).
    pub fn start_at(dir: &Path, args: &[&str], env: &[(&str, &str)], port: u16) -> Viewer {
        let port = port.to_string();
        let mut child = cli::command()
            .arg("view")
            .args(args)
            .args(["--port", port.as_str()])
            .envs(env.iter().copied())
            .current_dir(dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the binary runs");
        let (tx, rx) = mpsc::channel();
        let stdout = child.stdout.take().expect("piped stdout");
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        let (etx, erx) = mpsc::channel();
        let stderr = child.stderr.take().expect("piped stderr");
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = etx.send(line);
            }
        });
        let line = match rx.recv_timeout(Duration::from_secs(120)) {
            Ok(l) => l,
            Err(_) => {
                let _ = child.kill();
                let _ = child.wait();
                let err: Vec<String> = erx.try_iter().collect();
                panic!("verisplat view printed no URL: {}", err.join("\n"));
            }
        };
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://"))
            .unwrap_or_else(|| panic!("no URL in {line:?}"))
            .to_string();
        let port = url
            .trim_end_matches('/')
            .rsplit(':')
            .next()
            .and_then(|p| p.parse().ok())
            .unwrap_or_else(|| panic!("no port in {url}"));
        assert!(url.starts_with("http://127.0.0.1:"), "{url}");
        Viewer {
            child,
            url,
            port,
            stderr: erx,
        }
    }

    /// True while the process runs.
    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    pub fn connect(&self) -> Client {
        Client::connect(self.port)
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A decoded frame message.
pub struct Frame {
    pub header: Value,
    pub payload: Vec<u8>,
}

impl Frame {
    pub fn seq(&self) -> u64 {
        self.header["seq"].as_u64().unwrap_or(u64::MAX)
    }
    pub fn full(&self) -> bool {
        self.header["quality"] == "full"
    }
    /// The image, decoded, as RGB8.
    pub fn rgb(&self) -> image::RgbImage {
        image::load_from_memory(&self.payload)
            .expect("the frame decodes")
            .to_rgb8()
    }
}

/// What the server sent.
pub enum Incoming {
    Text(Value),
    Frame(Frame),
}

pub struct Client {
    pub ws: WebSocket<TcpStream>,
    pub hello: Value,
    seq: u64,
}

impl Client {
    pub fn connect(port: u16) -> Client {
        let stream = TcpStream::connect(("127.0.0.1", port)).expect("connect");
        stream
            .set_read_timeout(Some(Duration::from_secs(10)))
            .unwrap();
        let (ws, _) = tungstenite::client(format!("ws://127.0.0.1:{port}/ws"), stream)
            .expect("the WebSocket handshake");
        ws.get_ref()
            .set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        let mut c = Client {
            ws,
            hello: Value::Null,
            seq: 0,
        };
        match c.next(Duration::from_secs(10)) {
            Some(Incoming::Text(v)) if v["type"] == "hello" => c.hello = v,
            _ => panic!("no hello"),
        }
        c
    }

    /// The next message, or `None` at the deadline.
    pub fn next(&mut self, within: Duration) -> Option<Incoming> {
        let deadline = Instant::now() + within;
        while Instant::now() < deadline {
            match self.ws.read() {
                Ok(Message::Text(t)) => {
                    return Some(Incoming::Text(
                        serde_json::from_str(t.as_str()).expect("server text is JSON"),
                    ))
                }
                Ok(Message::Binary(b)) => {
                    let (header, payload) =
                        verisplat::app::view::protocol::split_binary(&b).expect("a framed binary");
                    return Some(Incoming::Frame(Frame {
                        header,
                        payload: payload.to_vec(),
                    }));
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                Err(e) => panic!("WebSocket failed: {e}"),
            }
        }
        None
    }

    /// Sends a message with a fresh `seq` (unless it has one); returns the seq.
    pub fn send(&mut self, mut msg: Value) -> u64 {
        self.seq += 1;
        if msg.get("seq").is_none() {
            msg["seq"] = self.seq.into();
        }
        let seq = msg["seq"].as_u64().unwrap_or(0);
        self.ws.send(Message::text(msg.to_string())).expect("send");
        seq
    }

    pub fn send_raw(&mut self, text: &str) {
        self.ws.send(Message::text(text.to_string())).expect("send");
    }

    /// Waits for a frame of request `seq` (full quality if `full`), skipping others;
    /// panics on an error message for `seq` or at the deadline.
    pub fn frame(&mut self, seq: u64, full: bool, within: Duration) -> Frame {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.next(left) {
                Some(Incoming::Frame(f))
                    if f.header["kind"] == "frame" && f.seq() == seq && f.full() == full =>
                {
                    return f
                }
                Some(Incoming::Text(v)) if v["type"] == "error" && v["seq"] == seq => {
                    panic!("request {seq} failed: {}", v["message"])
                }
                Some(_) => {}
                None => panic!(
                    "no {} frame for request {seq} within {within:?}",
                    if full { "full" } else { "preview" }
                ),
            }
        }
    }

    /// Waits for a binary message of header `kind` (`frame`, `screenshot`) for `seq`.
    pub fn frame_of_kind(&mut self, kind: &str, seq: u64, within: Duration) -> Frame {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.next(left) {
                Some(Incoming::Frame(f)) if f.header["kind"] == kind && f.seq() == seq => return f,
                Some(Incoming::Text(v)) if v["type"] == "error" && v["seq"] == seq => {
                    panic!("request {seq} failed: {}", v["message"])
                }
                Some(_) => {}
                None => panic!("no {kind} for request {seq} within {within:?}"),
            }
        }
    }

    /// Waits for a text message of `kind`, skipping frames and others.
    pub fn text(&mut self, kind: &str, within: Duration) -> Value {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.next(left) {
                Some(Incoming::Text(v)) if v["type"] == kind => return v,
                Some(_) => {}
                None => panic!("no {kind} message within {within:?}"),
            }
        }
    }

    /// A scene camera's entry from `hello`.
    pub fn camera(&self, k: usize) -> Value {
        self.hello["cameras"][k]["camera"].clone()
    }
}

pub fn read_rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Pixels that differ, and the largest channel difference.
pub fn diff(a: &image::RgbImage, b: &image::RgbImage) -> (usize, u8) {
    assert_eq!(a.dimensions(), b.dimensions());
    let mut n = 0;
    let mut max = 0;
    for (p, q) in a.pixels().zip(b.pixels()) {
        let d = (0..3).map(|c| p.0[c].abs_diff(q.0[c])).max().unwrap_or(0);
        if d > 0 {
            n += 1;
            max = max.max(d);
        }
    }
    (n, max)
}
