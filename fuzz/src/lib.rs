//! Helpers shared by the fuzz targets: splitting one input into two files, and a tiny SOG
//! bundle (4 Gaussians, SH degree 1) to put a fuzzed `meta.json` into.

use std::io::Write;
use std::sync::OnceLock;

/// Splits `data` at its first NUL byte into two parts (the second empty when there is none).
pub fn split_at_nul(data: &[u8]) -> (&[u8], &[u8]) {
    match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[]),
    }
}

/// Splits `data` as `len (u32 LE) | first (len bytes, clamped) | second`.
pub fn split_len_prefixed(data: &[u8]) -> (&[u8], &[u8]) {
    if data.len() < 4 {
        return (&[], &[]);
    }
    let len = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) as usize;
    let rest = &data[4..];
    let len = len.min(rest.len());
    (&rest[..len], &rest[len..])
}

/// The `meta.json` of [`tiny_sog_textures`]: 4 Gaussians, a 4-entry SH palette of band 1.
pub fn tiny_sog_meta() -> String {
    let codebook: Vec<String> = (0..256)
        .map(|i| format!("{}", -5.0 + i as f32 / 32.0))
        .collect();
    let cb = codebook.join(",");
    format!(
        r#"{{"version":2,"count":4,"means":{{"mins":[-1,-1,-1],"maxs":[1,1,1],"files":["means_l.webp","means_u.webp"]}},"scales":{{"codebook":[{cb}],"files":["scales.webp"]}},"quats":{{"files":["quats.webp"]}},"sh0":{{"codebook":[{cb}],"files":["sh0.webp"]}},"shN":{{"count":4,"bands":1,"codebook":[{cb}],"files":["shN_centroids.webp","shN_labels.webp"]}}}}"#
    )
}

fn webp(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut out)
        .encode(rgba, width, height, image::ExtendedColorType::Rgba8)
        .expect("encoding a small RGBA image as lossless WebP");
    out
}

/// The textures of a valid 4-Gaussian SOG (2x2 pixels; SH centroids 192x1), as
/// `(file name, WebP bytes)`, made once.
pub fn tiny_sog_textures() -> &'static [(String, Vec<u8>)] {
    static TEXTURES: OnceLock<Vec<(String, Vec<u8>)>> = OnceLock::new();
    TEXTURES.get_or_init(|| {
        let px = |f: &dyn Fn(usize) -> [u8; 4]| -> Vec<u8> { (0..4).flat_map(f).collect() };
        let centroids: Vec<u8> = (0..192)
            .flat_map(|i| [i as u8, 128, 255 - i as u8, 255])
            .collect();
        vec![
            (
                "means_l.webp".into(),
                webp(2, 2, &px(&|i| [17 * i as u8, 3, 250, 255])),
            ),
            (
                "means_u.webp".into(),
                webp(2, 2, &px(&|i| [60 * i as u8, 128, 200, 255])),
            ),
            (
                "scales.webp".into(),
                webp(2, 2, &px(&|i| [100 + i as u8, 90, 80, 255])),
            ),
            (
                "quats.webp".into(),
                webp(2, 2, &px(&|i| [128, 120, 140, 252 + i as u8])),
            ),
            (
                "sh0.webp".into(),
                webp(2, 2, &px(&|i| [150, 160, 170, 64 * i as u8])),
            ),
            ("shN_centroids.webp".into(), webp(192, 1, &centroids)),
            (
                "shN_labels.webp".into(),
                webp(2, 2, &px(&|i| [i as u8, 0, 0, 255])),
            ),
        ]
    })
}

/// A stored (uncompressed) zip of `meta.json` and the tiny SOG's textures.
pub fn sog_zip(meta: &[u8]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("meta.json", opts).expect("zip entry");
    zip.write_all(meta).expect("zip write");
    for (name, bytes) in tiny_sog_textures() {
        zip.start_file(name.as_str(), opts).expect("zip entry");
        zip.write_all(bytes).expect("zip write");
    }
    zip.finish().expect("zip finish").into_inner()
}
