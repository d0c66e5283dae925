//! The little HTTP/1.1 the viewer needs: a request head, a response, and the checks that
//! keep other web pages away from a viewer on loopback.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

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

/// Reads the request head; returns it and any bytes read past it.
pub(super) fn read_head(stream: &mut TcpStream) -> Option<(Request, Vec<u8>)> {
    let deadline = Instant::now() + HEAD_TIMEOUT;
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    let end = loop {
        if let Some(i) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            break i + 4;
        }
        if buf.len() > MAX_HEAD || Instant::now() > deadline {
            return None;
        }
        match stream.read(&mut chunk) {
            Ok(0) => return None,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
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
        buf[end..].to_vec(),
    ))
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

/// The Host header names a loopback address (`localhost`, `127.x.y.z`, `[::1]`, any
/// port). A server on loopback refuses other names, so a web page whose domain was
/// re-pointed at 127.0.0.1 (DNS rebinding) cannot reach it.
pub(super) fn loopback_host(req: &Request) -> bool {
    let Some(host) = req.header("Host") else {
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
/// open in the same browser may not drive the viewer.
pub(super) fn same_origin(req: &Request) -> bool {
    match (req.header("Origin"), req.header("Host")) {
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
        let req = |origin: Option<&str>| Request {
            method: "GET".into(),
            path: "/ws".into(),
            headers: [("Host", Some("127.0.0.1:8080")), ("Origin", origin)]
                .into_iter()
                .filter_map(|(n, v)| v.map(|v| (n.to_string(), v.to_string())))
                .collect(),
        };
        assert!(same_origin(&req(None)));
        assert!(same_origin(&req(Some("http://127.0.0.1:8080"))));
        assert!(!same_origin(&req(Some("http://evil.example"))));
        let host = |h: &str| Request {
            method: "GET".into(),
            path: "/".into(),
            headers: vec![("Host".into(), h.into())],
        };
        for ok in [
            "127.0.0.1:8080",
            "localhost:1",
            "LOCALHOST",
            "[::1]:9000",
            "127.3.2.1",
        ] {
            assert!(loopback_host(&host(ok)), "{ok}");
        }
        for bad in ["evil.example:8080", "10.0.0.1:8080", "[fe80::1]:80", ""] {
            assert!(!loopback_host(&host(bad)), "{bad}");
        }
    }
}
