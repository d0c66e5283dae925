//! Every input the fuzzers (`fuzz/`) found a crash, hang or runaway allocation with, kept
//! under `tests/data/fuzz_regressions/<target>/`, run through the parser of its target the
//! same way the fuzz target calls it: each must return (`Ok` or a one-line `Err` naming the
//! file) without panicking, quickly.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use verisplat::io;
use verisplat::io::camera::{KeyframePath, PathTiming};

/// A found input runs in well under this (they are small); more means a hang came back.
const PER_INPUT: Duration = Duration::from_secs(10);

/// How many found inputs each target's directory holds, targets in name order. Inputs
/// that are no longer found (a moved directory, a lost file) fail the test instead of
/// leaving nothing to run: add a target or raise its count with each input kept.
const EXPECTED: &[(&str, usize)] = &[("ply", 3)];

/// Runs `data` through the parser of fuzz target `target`, as `fuzz/fuzz_targets/<target>.rs`
/// does; returns the error message, if any.
fn run(target: &str, data: &[u8]) -> Result<(), String> {
    let p = Path::new;
    let text = || std::str::from_utf8(data).map_err(|e| format!("not UTF-8: {e}"));
    match target {
        "ply" => io::scene::ply::parse(data, p("fuzz.ply"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "splat" => {
            let _ = io::scene::splat::is_plausible(data);
            io::scene::splat::parse(data, p("fuzz.splat"))
                .map(drop)
                .map_err(|e| e.to_string())
        }
        "spz" => io::scene::spz::parse(data, p("fuzz.spz"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "compressed_ply" => io::scene::compressed_ply::parse(data, p("fuzz.compressed.ply"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "sog_zip" => io::scene::sog::parse_zip(data, p("fuzz.sog"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "detect" => io::scene::parse_bytes(data, p("fuzz.bin"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "cameras_json" => io::camera::parse_cameras_json(text()?, p("cameras.json"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "colmap_text" => {
            let (c, i) = match data.iter().position(|&b| b == 0) {
                Some(k) => (&data[..k], &data[k + 1..]),
                None => (data, &[][..]),
            };
            let (c, i) = (std::str::from_utf8(c), std::str::from_utf8(i));
            let (Ok(c), Ok(i)) = (c, i) else {
                return Err("not UTF-8".into());
            };
            io::camera::colmap::parse_colmap_text(c, p("cameras.txt"), i, p("images.txt"))
                .map(drop)
                .map_err(|e| e.to_string())
        }
        "colmap_binary" => {
            let (c, i) = if data.len() < 4 {
                (&[][..], &[][..])
            } else {
                let len = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) as usize;
                let rest = &data[4..];
                rest.split_at(len.min(rest.len()))
            };
            io::camera::colmap::parse_colmap_binary(c, p("cameras.bin"), i, p("images.bin"))
                .map(drop)
                .map_err(|e| e.to_string())
        }
        "nerfstudio" => io::camera::nerfstudio::parse_camera_path(text()?, p("camera_path.json"))
            .map(drop)
            .map_err(|e| e.to_string()),
        "keyframes" => {
            let path =
                KeyframePath::parse(text()?, p("keyframes.json")).map_err(|e| e.to_string())?;
            path.cameras(&PathTiming {
                frames: Some(1 + data.len() % 7),
                fps: None,
            })
            .map(drop)
            .map_err(|e| e.to_string())
        }
        "sog_meta" => {
            Err("sog_meta inputs need the fuzz crate's tiny SOG; store them as sog_zip".into())
        }
        other => panic!("unknown fuzz target directory {other}"),
    }
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz_regressions")
}

#[test]
fn every_found_input_gives_a_clean_result() {
    let mut count = 0;
    let mut per_target = Vec::new();
    let mut targets: Vec<_> = std::fs::read_dir(root())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    targets.sort();
    for dir in targets {
        let target = dir.file_name().unwrap().to_string_lossy().into_owned();
        let mut files: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        per_target.push((target.clone(), files.len()));
        for file in files {
            let data = std::fs::read(&file).unwrap();
            let start = Instant::now();
            let result = std::panic::catch_unwind(|| run(&target, &data));
            let name = file.strip_prefix(root()).unwrap().display().to_string();
            match result {
                Err(_) => panic!("{name}: the parser panicked"),
                Ok(Err(msg)) => assert!(!msg.contains('\n'), "{name}: not one line: {msg}"),
                Ok(Ok(())) => {}
            }
            assert!(
                start.elapsed() < PER_INPUT,
                "{name}: took {:?}",
                start.elapsed()
            );
            count += 1;
        }
    }
    eprintln!("{count} fuzz regression inputs ran cleanly");
    let expected: Vec<(String, usize)> = EXPECTED.iter().map(|&(t, n)| (t.into(), n)).collect();
    assert_eq!(per_target, expected, "inputs run per target");
    assert_eq!(count, EXPECTED.iter().map(|&(_, n)| n).sum::<usize>());
    assert!(count > 0, "no fuzz regression input ran");
}
