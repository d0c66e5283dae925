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

/// Why no request came: whether and how to answer.
#[derive(Debug, PartialEq)]
pub(super) enum HeadError {
    /// Nothing was sent (the client closed, the connection broke, or an idle socket
    /// reached the deadline): there is nobody to answer.
    Gone,
    /// Something that is not a request this server takes: answered with `status` and
    /// `reason` (one sentence) as plain text.
    Refused {
        status: &'static str,
        reason: String,
    },
}

fn refused(status: &'static str, reason: impl Into<String>) -> HeadError {
    HeadError::Refused {
        status,
        reason: reason.into(),
    }
}

/// Reads the request head (waiting [`HEAD_TIMEOUT`] at most): the request, every byte
/// read (the head and any bytes past it) and the length of the head. What is not an
/// HTTP/1 request head is refused as soon as that is clear (a TLS hello at once, not
/// after the deadline); one larger than [`MAX_HEAD`] with 431.
pub(super) fn read_head(stream: &mut TcpStream) -> Result<(Request, Vec<u8>, usize), HeadError> {
    let deadline = Instant::now() + HEAD_TIMEOUT;
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    let end = loop {
        if let Some(end) = head_end(&buf) {
            break end;
        }
        check_request_line(&buf)?;
        if buf.len() > MAX_HEAD {
            return Err(refused(
                "431 Request Header Fields Too Large",
                format!(
                    "the request head is over {} KiB, the most this server reads",
                    MAX_HEAD / 1024
                ),
            ));
        }
        let unfinished = |why: &str| {
            if buf.is_empty() {
                HeadError::Gone
            } else {
                refused(
                    "408 Request Timeout",
                    format!("the request head was not complete {why}"),
                )
            }
        };
        // One blocking read until the deadline (a zero time-out would mean none).
        let Some(left) = deadline
            .checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())
        else {
            return Err(unfinished(&format!("within {} s", HEAD_TIMEOUT.as_secs())));
        };
        stream
            .set_read_timeout(Some(left))
            .map_err(|_| HeadError::Gone)?;
        match stream.read(&mut chunk) {
            Ok(0) if buf.is_empty() => return Err(HeadError::Gone),
            Ok(0) => return Err(refused(
                "400 Bad Request",
                "the connection ended inside the request head (no empty line after the headers)",
            )),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                return Err(unfinished(&format!("within {} s", HEAD_TIMEOUT.as_secs())))
            }
            Err(_) => return Err(HeadError::Gone),
        }
    };
    let request = parse_head(&buf[..end])?;
    Ok((request, buf, end))
}

/// The end of the head (past its empty line), if it was all read. Bare `\n` line ends
/// are taken too, as most servers do.
fn head_end(buf: &[u8]) -> Option<usize> {
    let crlf = buf.windows(4).position(|w| w == b"\r\n\r\n").map(|i| i + 4);
    let lf = buf.windows(2).position(|w| w == b"\n\n").map(|i| i + 2);
    match (crlf, lf) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Refuses a request line that cannot become `METHOD TARGET HTTP/1.x` once read in
/// full (bytes that are not printable ASCII; a line that is over and wrong).
fn check_request_line(buf: &[u8]) -> Result<(), HeadError> {
    let line_end = buf.iter().position(|&b| b == b'\n');
    let line = &buf[..line_end.unwrap_or(buf.len())];
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    if buf.first() == Some(&0x16) {
        return Err(refused(
            "400 Bad Request",
            "this is a TLS handshake, and the viewer speaks plain HTTP: open http://, not https://",
        ));
    }
    if let Some(bad) = line.iter().find(|&&b| !(b' '..=b'~').contains(&b)) {
        return Err(refused(
            "400 Bad Request",
            format!("not an HTTP request: byte 0x{bad:02x} in the request line"),
        ));
    }
    if line_end.is_some() {
        request_line(line)?;
    }
    Ok(())
}

/// `METHOD TARGET HTTP/1.x`, split.
fn request_line(line: &[u8]) -> Result<(String, String), HeadError> {
    let text = std::str::from_utf8(line).unwrap_or("");
    let parts: Vec<&str> = text.split(' ').collect();
    let shown: String = text.chars().take(60).collect();
    match parts.as_slice() {
        [method, target, version]
            if !method.is_empty()
                && method.bytes().all(|b| b.is_ascii_alphabetic())
                && target.starts_with('/') =>
        {
            if version.starts_with("HTTP/1.") {
                Ok((method.to_string(), target.to_string()))
            } else {
                Err(refused(
                    "505 HTTP Version Not Supported",
                    format!("the viewer speaks HTTP/1.1, the request is {version}"),
                ))
            }
        }
        _ => Err(refused(
            "400 Bad Request",
            format!("not an HTTP request line: {shown:?} (expected METHOD /path HTTP/1.1)"),
        )),
    }
}

fn parse_head(head: &[u8]) -> Result<Request, HeadError> {
    let text = std::str::from_utf8(head)
        .map_err(|_| refused("400 Bad Request", "the request head is not UTF-8 text"))?;
    let mut lines = text.split('\n').map(|l| l.strip_suffix('\r').unwrap_or(l));
    let (method, path) = request_line(lines.next().unwrap_or("").as_bytes())?;
    let mut headers = Vec::new();
    for line in lines.take_while(|l| !l.is_empty()) {
        let Some((name, value)) = line.split_once(':') else {
            let shown: String = line.chars().take(60).collect();
            return Err(refused(
                "400 Bad Request",
                format!("a header line without a colon: {shown:?}"),
            ));
        };
        headers.push((name.trim().to_string(), value.trim().to_string()));
    }
    Ok(Request {
        method,
        path,
        headers,
    })
}

/// Answers a refused request with `status` and its reason, and lets the client read
/// the answer: the sending side is shut first, then what the client still sends (the
/// rest of an oversized head) is read and dropped for a moment, since closing a socket
/// with unread bytes resets the connection and the client would lose the answer.
pub(super) fn refuse(stream: &mut TcpStream, status: &str, reason: &str) {
    respond(
        stream,
        status,
        "text/plain; charset=utf-8",
        format!("{reason}\n").as_bytes(),
    );
    let _ = stream.shutdown(std::net::Shutdown::Write);
    drain(stream, LINGER);
}

/// How long [`refuse`] (and a WebSocket closed for an oversized message) reads what the
/// client still sends before closing.
pub(super) const LINGER: Duration = Duration::from_secs(5);

/// Reads and drops what arrives on `stream` until the client closes, an error, or `for_`
/// passed.
pub(super) fn drain(stream: &TcpStream, for_: Duration) {
    let deadline = Instant::now() + for_;
    let mut sink = vec![0u8; 64 * 1024];
    let mut reader = stream;
    while let Some(left) = deadline
        .checked_duration_since(Instant::now())
        .filter(|d| !d.is_zero())
    {
        if reader.set_read_timeout(Some(left)).is_err() {
            return;
        }
        match reader.read(&mut sink) {
            Ok(0) => return,
            Ok(_) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => return,
        }
    }
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
    fn request_heads_parse_or_are_refused_with_a_status() {
        let status = |head: &[u8]| -> &'static str {
            if let Err(e) = check_request_line(head) {
                return match e {
                    HeadError::Refused { status, .. } => status,
                    HeadError::Gone => "gone",
                };
            }
            match head_end(head).map(|end| parse_head(&head[..end])) {
                None => "incomplete",
                Some(Ok(_)) => "ok",
                Some(Err(HeadError::Refused { status, .. })) => status,
                Some(Err(HeadError::Gone)) => "gone",
            }
        };
        assert_eq!(status(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n"), "ok");
        assert_eq!(status(b"GET /viewer.js HTTP/1.0\n\n"), "ok");
        assert_eq!(status(b"GET / HTTP/1.1\r\nHost"), "incomplete");
        assert_eq!(status(b"GE"), "incomplete");
        assert_eq!(status(b"garbage\r\n\r\n"), "400 Bad Request");
        assert_eq!(status(b"hello world\n"), "400 Bad Request");
        assert_eq!(status(b"\x16\x03\x01\x02\x00"), "400 Bad Request");
        assert_eq!(status(b"\x00\x01garbage"), "400 Bad Request");
        assert_eq!(
            status(b"GET / HTTP/2.0\r\n\r\n"),
            "505 HTTP Version Not Supported"
        );
        assert_eq!(
            status(b"GET / HTTP/1.1\r\nno colon here\r\n\r\n"),
            "400 Bad Request"
        );
        let parsed = parse_head(b"GET /ws?x HTTP/1.1\r\nHost:  a:1 \r\n\r\n").unwrap();
        assert_eq!(
            (parsed.method.as_str(), parsed.path.as_str()),
            ("GET", "/ws?x")
        );
        assert_eq!(parsed.header("host"), Some("a:1"));
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
