//! PlayCanvas SOG cases: a 4-Gaussian bundle with 2x2 textures as a zip or a directory,
//! and the cases for both.

use super::case::{scene_case, Case, Expect, Kind};
use std::io::Write;

// SOG: a 4-Gaussian bundle with 2x2 textures (and a 192x1 SH palette).

pub(super) fn webp(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut out)
        .encode(rgba, width, height, image::ExtendedColorType::Rgba8)
        .unwrap();
    out
}

pub(super) fn sog_meta(
    count: &str,
    version: &str,
    codebook_len: usize,
    sh_count: u32,
    files_means: &str,
) -> String {
    let cb: Vec<String> = (0..256)
        .map(|i| format!("{}", -5.0 + i as f32 / 32.0))
        .collect();
    let short: Vec<String> = (0..codebook_len)
        .map(|i| format!("{}", i as f32 / 64.0))
        .collect();
    let (cb, short) = (cb.join(","), short.join(","));
    format!(
        r#"{{"version":{version},"count":{count},"means":{{"mins":[-1,-1,-1],"maxs":[1,1,1],"files":[{files_means}]}},"scales":{{"codebook":[{short}],"files":["scales.webp"]}},"quats":{{"files":["quats.webp"]}},"sh0":{{"codebook":[{cb}],"files":["sh0.webp"]}},"shN":{{"count":{sh_count},"bands":1,"codebook":[{cb}],"files":["shN_centroids.webp","shN_labels.webp"]}}}}"#
    )
}

pub(super) fn good_sog_meta() -> String {
    sog_meta("4", "2", 256, 4, r#""means_l.webp","means_u.webp""#)
}

/// A stored zip of `meta` and the tiny SOG's textures, with `replace` swapping one of them.
pub(super) fn sog_zip(meta: &str, replace: Option<(&str, Vec<u8>)>) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in sog_files(meta) {
        let bytes = match &replace {
            Some((r, b)) if *r == name => b.clone(),
            _ => bytes,
        };
        zip.start_file(name, opts).unwrap();
        zip.write_all(&bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// The files of the tiny SOG: `meta` and its WebP textures.
pub(super) fn sog_files(meta: &str) -> Vec<(&'static str, Vec<u8>)> {
    let px = |f: &dyn Fn(u8) -> [u8; 4]| -> Vec<u8> { (0..4u8).flat_map(f).collect() };
    let centroids: Vec<u8> = (0..192u32)
        .flat_map(|i| [i as u8, 128, 255 - i as u8, 255])
        .collect();
    let files: Vec<(&str, Vec<u8>)> = vec![
        ("meta.json", meta.as_bytes().to_vec()),
        ("means_l.webp", webp(2, 2, &px(&|i| [17 * i, 3, 250, 255]))),
        (
            "means_u.webp",
            webp(2, 2, &px(&|i| [60 * i, 128, 127, 255])),
        ),
        ("scales.webp", webp(2, 2, &px(&|i| [100 + i, 90, 80, 255]))),
        ("quats.webp", webp(2, 2, &px(&|i| [128, 120, 140, 252 + i]))),
        ("sh0.webp", webp(2, 2, &px(&|i| [150, 160, 170, 200 + i]))),
        ("shN_centroids.webp", webp(192, 1, &centroids)),
        ("shN_labels.webp", webp(2, 2, &px(&|i| [i, 0, 0, 255]))),
    ];
    files
}

/// An unbundled SOG directory `sog/` (loaded as the directory).
pub(super) fn sog_dir_case(name: &'static str, meta: &str, expect: Expect) -> Case {
    let names = [
        "sog/meta.json",
        "sog/means_l.webp",
        "sog/means_u.webp",
        "sog/scales.webp",
        "sog/quats.webp",
        "sog/sh0.webp",
        "sog/shN_centroids.webp",
        "sog/shN_labels.webp",
    ];
    let files = sog_files(meta);
    assert_eq!(files.len(), names.len());
    Case {
        name,
        kind: Kind::Scene,
        files: names
            .into_iter()
            .zip(files.into_iter().map(|(_, b)| b))
            .collect(),
        arg: "sog",
        expect,
    }
}

/// The table's cases for PlayCanvas SOG (zip bundles).
pub(super) fn sog_zip_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    let two_40 = "1099511627776";
    vec![
        scene_case(
            "sog_not_a_zip",
            "s.sog",
            b"PK\x03\x04 this is not a zip archive".to_vec(),
            Error("is not a readable zip archive"),
        ),
        scene_case(
            "sog_zip_truncated",
            "s.sog",
            {
                let z = sog_zip(&good_sog_meta(), None);
                z[..z.len() / 2].to_vec()
            },
            Error("is not a readable zip archive"),
        ),
        scene_case(
            "sog_bad_json",
            "s.sog",
            sog_zip("{\"version\": 2, \"count\": ", None),
            Error("has a SOG meta.json that is not valid"),
        ),
        scene_case(
            "sog_version_3",
            "s.sog",
            sog_zip(
                &sog_meta("4", "3", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("is SOG version 3"),
        ),
        scene_case(
            "sog_count_2_pow_40",
            "s.sog",
            sog_zip(
                &sog_meta(two_40, "2", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("too small for the 1099511627776 Gaussians"),
        ),
        scene_case(
            "sog_count_negative",
            "s.sog",
            sog_zip(
                &sog_meta("-4", "2", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("has a SOG meta.json that is not valid"),
        ),
        scene_case(
            "sog_short_codebook",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 10, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("SOG scales codebook of 10 entries"),
        ),
        scene_case(
            "sog_too_few_files",
            "s.sog",
            sog_zip(&sog_meta("4", "2", 256, 4, r#""means_l.webp""#), None),
            Error("whose means entry lists too few files"),
        ),
        scene_case(
            "sog_path_traversal",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 256, 4, r#""../means_l.webp","means_u.webp""#),
                None,
            ),
            Error("only plain file names beside meta.json are allowed"),
        ),
        scene_case(
            "sog_missing_entry",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 256, 4, r#""means_l.webp","nope.webp""#),
                None,
            ),
            Error("without a readable \"nope.webp\" entry"),
        ),
        scene_case(
            "sog_texture_not_webp",
            "s.sog",
            sog_zip(
                &good_sog_meta(),
                Some(("quats.webp", b"RIFF\x10\0\0\0WEBPjunkjunk".to_vec())),
            ),
            Error("cannot decode its SOG texture \"quats.webp\""),
        ),
        scene_case(
            "sog_texture_too_small",
            "s.sog",
            sog_zip(
                &good_sog_meta(),
                Some(("sh0.webp", webp(1, 1, &[1, 2, 3, 4]))),
            ),
            Error("\"sh0.webp\" of 1x1 pixels, too small for the 4 Gaussians"),
        ),
        scene_case(
            "sog_bad_quaternion_tag",
            "s.sog",
            sog_zip(
                &good_sog_meta(),
                Some(("quats.webp", webp(2, 2, &[128, 128, 128, 7].repeat(4)))),
            ),
            Error("invalid quaternion tag 7 for Gaussian 0"),
        ),
        scene_case(
            "sog_palette_label_too_large",
            "s.sog",
            sog_zip(
                &sog_meta("4", "2", 256, 2, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Error("SH palette label 2 for Gaussian 2"),
        ),
        scene_case(
            "sog_zero_gaussians",
            "s.sog",
            sog_zip(
                &sog_meta("0", "2", 256, 4, r#""means_l.webp","means_u.webp""#),
                None,
            ),
            Renders(0),
        ),
        scene_case(
            "sog_four_gaussians",
            "s.sog",
            sog_zip(&good_sog_meta(), None),
            Renders(4),
        ),
    ]
}

/// The table's cases for PlayCanvas SOG (unbundled directories).
pub(super) fn sog_dir_cases() -> Vec<Case> {
    use Expect::{Error, Renders};
    let two_40 = "1099511627776";
    vec![
        sog_dir_case(
            "sog_dir_count_2_pow_40",
            &sog_meta(two_40, "2", 256, 4, r#""means_l.webp","means_u.webp""#),
            Error("too small for the 1099511627776 Gaussians"),
        ),
        sog_dir_case(
            "sog_dir_bad_json",
            "{\"version\": 2, \"count\": 4,",
            Error("has a SOG meta.json that is not valid"),
        ),
        sog_dir_case(
            "sog_dir_path_traversal",
            &sog_meta("4", "2", 256, 4, r#""../sog/means_l.webp","means_u.webp""#),
            Error("only plain file names beside meta.json are allowed"),
        ),
        sog_dir_case("sog_dir_four_gaussians", &good_sog_meta(), Renders(4)),
    ]
}
