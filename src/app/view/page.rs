//! The viewer page: `page/index.html`, `page/viewer.js` and `page/viewer.css`, embedded
//! in the binary (no build step, nothing fetched from elsewhere).

/// The page's HTML.
pub const INDEX_HTML: &str = include_str!("page/index.html");
/// The page's script: controls, camera, the WebSocket client.
pub const VIEWER_JS: &str = include_str!("page/viewer.js");
/// The page's style.
pub const VIEWER_CSS: &str = include_str!("page/viewer.css");

/// The content type and bytes served at `path`, if it is one of the page's files.
pub fn file(path: &str) -> Option<(&'static str, &'static [u8])> {
    match path {
        "/" | "/index.html" => Some(("text/html; charset=utf-8", INDEX_HTML.as_bytes())),
        "/viewer.js" => Some(("text/javascript; charset=utf-8", VIEWER_JS.as_bytes())),
        "/viewer.css" => Some(("text/css; charset=utf-8", VIEWER_CSS.as_bytes())),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_page_loads_only_its_own_files() {
        for text in [super::INDEX_HTML, super::VIEWER_JS, super::VIEWER_CSS] {
            assert!(!text.contains("https://") && !text.contains("http://"));
        }
        assert!(super::INDEX_HTML.contains("viewer.js"));
        assert!(super::file("/../Cargo.toml").is_none());
    }
}
