//! The little HTTP/1.1 the viewer needs: a request head, a response, and the checks that
//! keep other web pages away from a viewer on loopback.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};
use tungstenite::handshake::server::ErrorResponse;
use tungstenite::http::{HeaderValue, StatusCode};

/// How long a connection may take to send its HTTP request head.
pub(super) const HEAD_TIMEOUT: Duration = Duration::from_secs(5);
/// Longest HTTP request head read.
pub(super) const MAX_HEAD: usize = 16 * 1024;
/// A parsed HTTP request head.
pub(super) struct Request {
    pub(super) method: String,
    pub(super) path: String,
    pub(super) headers: Vec<(String, String)>,
}

impl Request {
    pub(super) fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

/// Reads the request head (waiting [`HEAD_TIMEOUT`] at most): the request, every byte
/// read (the head and any bytes past it) and the length of the head.
pub(super) fn read_head(stream: &mut TcpStream) -> Option<(Request, Vec<u8>, usize)> {
    let deadline = Instant::now() + HEAD_TIMEOUT;
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    let end = loop {
        if let Some(i) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            break i + 4;
        }
        if buf.len() > MAX_HEAD {
            return None;
        }
        // One blocking read until the deadline (a zero time-out would mean none).
        let left = deadline
            .checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())?;
        stream.set_read_timeout(Some(left)).ok()?;
        match stream.read(&mut chunk) {
            Ok(0) => return None,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            // The deadline (WouldBlock or TimedOut) or a broken connection.
            Err(_) => return None,
        }
    };
    let text = std::str::from_utf8(&buf[..end]).ok()?;
    let mut lines = text.split("\r\n");
    let mut first = lines.next()?.split(' ');
    let method = first.next()?.to_string();
    let path = first.next()?.to_string();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(n, v)| (n.trim().to_string(), v.trim().to_string()))
        .collect();
    Some((
        Request {
            method,
            path,
            headers,
        },
        buf,
        end,
    ))
}

/// The request is a WebSocket handshake tungstenite's `accept` takes: it checks the same
/// (GET, `Connection: Upgrade`, `Upgrade: websocket`, version 13, a key).
pub(super) fn websocket_handshake(req: &Request) -> bool {
    let mut builder = tungstenite::http::Request::builder()
        .method(req.method.as_str())
        .uri(req.path.as_str());
    for (name, value) in &req.headers {
        builder = builder.header(name.as_str(), value.as_str());
    }
    builder
        .body(())
        .is_ok_and(|r| tungstenite::handshake::server::create_response(&r).is_ok())
}

pub(super) fn respond(stream: &mut TcpStream, status: &str, content_type: &str, body: &[u8]) {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        body.len()
    );
    let _ = stream
        .write_all(head.as_bytes())
        .and_then(|()| stream.write_all(body))
        .and_then(|()| stream.flush());
}

/// A refused WebSocket handshake: `status` with a plain-text `body` and the headers
/// [`respond`] sends, for tungstenite to write (its callback's error).
pub(super) fn refusal(status: StatusCode, body: &str) -> ErrorResponse {
    let mut response = ErrorResponse::new(Some(body.to_string()));
    *response.status_mut() = status;
    let headers = response.headers_mut();
    headers.insert("content-type", HeaderValue::from_static("text/plain"));
    headers.insert("content-length", HeaderValue::from(body.len()));
    headers.insert("cache-control", HeaderValue::from_static("no-store"));
    headers.insert(
        "x-content-type-options",
        HeaderValue::from_static("nosniff"),
    );
    headers.insert("connection", HeaderValue::from_static("close"));
    response
}

/// The Host header names a loopback address (`localhost`, `127.x.y.z`, `[::1]`, any
/// port). A server on loopback refuses other names, so a web page whose domain was
/// re-pointed at 127.0.0.1 (DNS rebinding) cannot reach it.
pub(super) fn loopback_host(host: Option<&str>) -> bool {
    let Some(host) = host else {
        return false;
    };
    let name = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or(""),
        None => host.rsplit_once(':').map_or(host, |(n, _)| n),
    };
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Origin `http://host:port` must name the Host the page was loaded from: another site
/// open in the same browser may not drive the viewer. (No Origin: not a browser.)
pub(super) fn same_origin(origin: Option<&str>, host: Option<&str>) -> bool {
    match (origin, host) {
        (None, _) => true,
        (Some(origin), Some(host)) => origin
            .strip_prefix("http://")
            .is_some_and(|o| o.eq_ignore_ascii_case(host)),
        (Some(_), None) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_must_match_host() {
        let host = Some("127.0.0.1:8080");
        assert!(same_origin(None, host));
        assert!(same_origin(Some("http://127.0.0.1:8080"), host));
        assert!(!same_origin(Some("http://evil.example"), host));
        assert!(!same_origin(Some("http://127.0.0.1:8080"), None));
        for ok in [
            "127.0.0.1:8080",
            "localhost:1",
            "LOCALHOST",
            "[::1]:9000",
            "127.3.2.1",
        ] {
            assert!(loopback_host(Some(ok)), "{ok}");
        }
        for bad in ["evil.example:8080", "10.0.0.1:8080", "[fe80::1]:80", ""] {
            assert!(!loopback_host(Some(bad)), "{bad}");
        }
        assert!(!loopback_host(None));
    }

    #[test]
    fn websocket_handshakes_are_told_apart() {
        let req = |headers: &[(&str, &str)]| Request {
            method: "GET".into(),
            path: "/ws".into(),
            headers: headers
                .iter()
                .map(|(n, v)| (n.to_string(), v.to_string()))
                .collect(),
        };
        let full = [
            ("Host", "127.0.0.1:8080"),
            ("Connection", "keep-alive, Upgrade"),
            ("Upgrade", "websocket"),
            ("Sec-WebSocket-Version", "13"),
            ("Sec-WebSocket-Key", "dGhlIHNhbXBsZSBub25jZQ=="),
        ];
        assert!(websocket_handshake(&req(&full)));
        for left_out in 1..full.len() {
            let mut headers = full.to_vec();
            headers.remove(left_out);
            assert!(!websocket_handshake(&req(&headers)), "{left_out}");
        }
        let post = Request {
            method: "POST".into(),
            ..req(&full)
        };
        assert!(!websocket_handshake(&post));
    }

    #[test]
    fn refusals_are_complete_responses() {
        let r = refusal(StatusCode::FORBIDDEN, "no\n");
        let mut out = Vec::new();
        tungstenite::handshake::server::write_response(&mut out, &r).unwrap();
        let head = String::from_utf8(out).unwrap();
        assert!(head.starts_with("HTTP/1.1 403 Forbidden\r\n"), "{head}");
        assert!(head.contains("content-length: 3\r\n"), "{head}");
        assert_eq!(r.body().as_deref(), Some("no\n"));
    }
}
