//! glTF `KHR_gaussian_splatting` in and out: round trips of the shared scenes, the axis
//! change splat-transform uses, node transforms, merged primitives, quantised attributes,
//! the SPZ-compressed variant, and clear errors for broken files.

use crate::common;
use glam::{DMat3, DQuat, DVec3, Vec3};
use serde_json::{json, Value};
use std::path::Path;
use verisplat::core::model::sh::eval_sh;
use verisplat::core::scene;
use verisplat::core::scene::Scene;
use verisplat::cpu::{self, RenderOptions};
use verisplat::io;
use verisplat::io::metrics;
use verisplat::io::scene::{gltf_write, spz, SceneFormat};

/// The JSON document and BIN chunk of a GLB.
fn glb_parts(glb: &[u8]) -> (Value, Vec<u8>) {
    let json_len = u32::from_le_bytes(glb[12..16].try_into().unwrap()) as usize;
    let doc = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    let bin_len = u32::from_le_bytes(glb[bin_at..bin_at + 4].try_into().unwrap()) as usize;
    (doc, glb[bin_at + 8..bin_at + 8 + bin_len].to_vec())
}

/// A GLB of `doc` and `bin`.
fn glb_pack(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut json = serde_json::to_vec(doc).unwrap();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut doc_bytes = Vec::new();
    doc_bytes.extend(b"glTF");
    doc_bytes.extend(2u32.to_le_bytes());
    doc_bytes.extend(((28 + json.len() + bin.len()) as u32).to_le_bytes());
    doc_bytes.extend((json.len() as u32).to_le_bytes());
    doc_bytes.extend(b"JSON");
    doc_bytes.extend(json);
    doc_bytes.extend((bin.len() as u32).to_le_bytes());
    doc_bytes.extend(b"BIN\0");
    doc_bytes.extend(bin);
    doc_bytes
}

fn parse(bytes: &[u8]) -> Result<(Scene, SceneFormat), String> {
    io::scene::parse_bytes(bytes, Path::new("t.glb")).map_err(|e| e.to_string())
}

/// The covariance of Gaussian `i`, in f64.
fn covariance(s: &Scene, i: usize) -> DMat3 {
    let [w, x, y, z] = s.rotations[i];
    let r = DMat3::from_quat(DQuat::from_xyzw(x as f64, y as f64, z as f64, w as f64).normalize());
    let l = s.log_scales[i];
    let d = DMat3::from_diagonal(DVec3::new(
        (2.0 * l[0] as f64).exp(),
        (2.0 * l[1] as f64).exp(),
        (2.0 * l[2] as f64).exp(),
    ));
    r * d * r.transpose()
}

fn max_abs(m: DMat3) -> f64 {
    m.to_cols_array().iter().fold(0.0f64, |a, v| a.max(v.abs()))
}

/// PSNR of CPU reference renders of `a` and `b` from three orbit cameras of the playbot.
fn render_psnr(a: &Scene, b: &Scene, cams: &str) -> f64 {
    let (aa, ba) = (a.activated(), b.activated());
    [2, 9, 17]
        .iter()
        .map(|&i| {
            let cam = common::orbit(cams, i, 256, 160);
            let fa = cpu::render(&aa, &cam, &RenderOptions::default());
            let fb = cpu::render(&ba, &cam, &RenderOptions::default());
            let ca: Vec<f32> = fa.color.iter().flatten().copied().collect();
            let cb: Vec<f32> = fb.color.iter().flatten().copied().collect();
            metrics::psnr(&ca, &cb, 1.0)
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn shared_scenes_round_trip_through_glb() {
    for (file, cams) in [
        (
            "playbot_lod6_1873_sh2.ply",
            Some("playbot_orbit_cameras.synthetic.json"),
        ),
        (
            "playbot_lod3_31k_sh2.ply",
            Some("playbot_orbit_cameras.synthetic.json"),
        ),
        ("train3_sh3.ply", None),
    ] {
        let source = common::shared_scene(file);
        let glb = gltf_write::to_glb(&source).unwrap();
        let (back, format) = parse(&glb).unwrap();
        assert!(
            matches!(format, SceneFormat::Gltf(i) if i.binary && i.primitives == 1),
            "{format}"
        );
        assert_eq!(
            (back.len(), back.sh_degree),
            (source.len(), source.sh_degree),
            "{file}"
        );
        // The half turn is a negation: centres and SH come back bit for bit.
        assert_eq!(back.positions, source.positions, "{file}");
        assert_eq!(back.sh, source.sh, "{file}");
        for i in 0..source.len() {
            let (a, b) = (covariance(&source, i), covariance(&back, i));
            let rel = max_abs(a - b) / max_abs(a);
            assert!(rel < 2e-6, "{file} Gaussian {i}: covariance off by {rel:e}");
            let (pa, pb) = (
                scene::sigmoid(source.opacity_logits[i]),
                scene::sigmoid(back.opacity_logits[i]),
            );
            assert!(
                (pa - pb).abs() < 1e-6,
                "{file} Gaussian {i}: opacity {pa} -> {pb}"
            );
        }
        if let Some(cams) = cams {
            // Measured: 173 dB (lod6) and 169 dB (lod3): f32 rounding of exp/ln and
            // sigmoid/logit only.
            let p = render_psnr(&source, &back, cams);
            assert!(p >= 120.0, "{file}: renders {p:.1} dB apart");
        }
    }
}

#[test]
fn the_file_is_in_gltf_axes_as_splat_transform_writes_them() {
    let source = common::shared_scene("train3_sh3.ply");
    let (doc, bin) = glb_parts(&gltf_write::to_glb(&source).unwrap());
    let attrs = &doc["meshes"][0]["primitives"][0]["attributes"];
    let read = |name: &str, comps: usize| -> Vec<f32> {
        let acc = &doc["accessors"][attrs[name].as_u64().unwrap() as usize];
        let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let off = view["byteOffset"].as_u64().unwrap() as usize;
        (0..source.len() * comps)
            .map(|k| f32::from_le_bytes(bin[off + 4 * k..off + 4 * k + 4].try_into().unwrap()))
            .collect()
    };
    let pos = read("POSITION", 3);
    let rot = read("KHR_gaussian_splatting:ROTATION", 4);
    let sh1 = read("KHR_gaussian_splatting:SH_DEGREE_1_COEF_0", 3);
    let sh1m0 = read("KHR_gaussian_splatting:SH_DEGREE_1_COEF_1", 3);
    let opacity = read("KHR_gaussian_splatting:OPACITY", 1);
    let stride = source.sh_stride();
    for i in 0..source.len() {
        let p = source.positions[i];
        // (x, y, z)_gltf = (-x, -y, z)_ply: a half turn about z, as splat-transform 3.7
        // writes its .glb (its Transform.PLY, Euler (0, 0, 180)).
        assert_eq!(&pos[3 * i..3 * i + 3], &[-p[0], -p[1], p[2]]);
        // The rotation is the half turn times ours, unit length, x y z w.
        let [w, x, y, z] = source.rotations[i];
        let q = DQuat::from_rotation_z(std::f64::consts::PI)
            * DQuat::from_xyzw(x as f64, y as f64, z as f64, w as f64).normalize();
        let g = DQuat::from_xyzw(
            rot[4 * i] as f64,
            rot[4 * i + 1] as f64,
            rot[4 * i + 2] as f64,
            rot[4 * i + 3] as f64,
        );
        assert!((g.length() - 1.0).abs() < 1e-6);
        assert!(q.dot(g).abs() > 1.0 - 1e-6, "Gaussian {i}: {q:?} vs {g:?}");
        // Band 1 (y, z, x): m = -1 and m = 1 change sign under the half turn, m = 0 not.
        for c in 0..3 {
            assert_eq!(sh1[3 * i + c], -source.sh[i * stride + 3 + c]);
            assert_eq!(sh1m0[3 * i + c], source.sh[i * stride + 6 + c]);
        }
        assert_eq!(opacity[i], scene::sigmoid(source.opacity_logits[i]));
    }
    let ext = &doc["meshes"][0]["primitives"][0]["extensions"]["KHR_gaussian_splatting"];
    assert_eq!(ext["kernel"], "ellipse");
    assert_eq!(ext["colorSpace"], "srgb_rec709_display");
    assert_eq!(doc["meshes"][0]["primitives"][0]["mode"], 0);
}

/// A small scene of a few Gaussians at SH degree `deg`, with distinct values.
fn small(deg: u32, seed: u64) -> Scene {
    common::random_scene(24, deg, seed)
}

/// The colour of Gaussian `i` seen along `dir`.
fn colour(s: &Scene, i: usize, dir: Vec3) -> [f32; 3] {
    let k = s.sh_stride();
    eval_sh(s.sh_degree, &s.sh[i * k..(i + 1) * k], dir)
}

#[test]
fn node_transforms_move_centres_shapes_and_colours() {
    let source = small(3, 7);
    let (mut doc, bin) = glb_parts(&gltf_write::to_glb(&source).unwrap());
    // A parent translates; its child (holding the mesh) rotates and scales uniformly.
    let axis = DVec3::new(1.0, 2.0, -0.5).normalize();
    let rot = DQuat::from_axis_angle(axis, 0.7);
    doc["nodes"] = json!([
        { "children": [1], "translation": [0.5, -1.0, 2.0] },
        { "mesh": 0, "rotation": [rot.x, rot.y, rot.z, rot.w], "scale": [1.5, 1.5, 1.5] }
    ]);
    let (back, _) = parse(&glb_pack(&doc, &bin)).unwrap();
    // The same transform in our frame: H M H with H the half turn about z.
    let h = DMat3::from_rotation_z(std::f64::consts::PI);
    let m = h * DMat3::from_quat(rot) * 1.5 * h;
    let t = h * DVec3::new(0.5, -1.0, 2.0);
    let q = h * DMat3::from_quat(rot) * h;
    for i in 0..source.len() {
        let p = source.positions[i];
        let want = m * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) + t;
        let got = back.positions[i];
        let err = (want - DVec3::new(got[0] as f64, got[1] as f64, got[2] as f64)).length();
        assert!(err < 1e-5, "Gaussian {i}: centre off by {err}");
        let want = m * covariance(&source, i) * m.transpose();
        let rel = max_abs(want - covariance(&back, i)) / max_abs(want);
        assert!(rel < 1e-5, "Gaussian {i}: covariance off by {rel:e}");
        // The colour seen along q d after is the colour seen along d before.
        for d in [
            Vec3::X,
            Vec3::new(0.3, -0.8, 0.5).normalize(),
            Vec3::new(-0.6, 0.1, 0.79).normalize(),
        ] {
            let turned = (q * d.as_dvec3()).as_vec3();
            let (a, b) = (colour(&source, i, d), colour(&back, i, turned));
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() < 1e-4,
                    "Gaussian {i} along {d}: {a:?} vs {b:?}"
                );
            }
        }
    }
}

#[test]
fn a_non_uniform_node_scale_scales_each_covariance() {
    let source = small(1, 11);
    let (mut doc, bin) = glb_parts(&gltf_write::to_glb(&source).unwrap());
    // A column-major matrix: a quarter turn about y times diag(2, 0.5, 1), then a shift.
    let r = DMat3::from_rotation_y(std::f64::consts::FRAC_PI_2);
    let s = DMat3::from_diagonal(DVec3::new(2.0, 0.5, 1.0));
    let lin = r * s;
    let mut matrix: Vec<f64> = Vec::new();
    for col in [lin.x_axis, lin.y_axis, lin.z_axis] {
        matrix.extend([col.x, col.y, col.z, 0.0]);
    }
    matrix.extend([1.0, 2.0, 3.0, 1.0]);
    doc["nodes"][0]["matrix"] = json!(matrix);
    let (back, _) = parse(&glb_pack(&doc, &bin)).unwrap();
    let h = DMat3::from_rotation_z(std::f64::consts::PI);
    let m = h * lin * h;
    for i in 0..source.len() {
        let p = source.positions[i];
        let want =
            m * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) + h * DVec3::new(1.0, 2.0, 3.0);
        let got = DVec3::new(
            back.positions[i][0] as f64,
            back.positions[i][1] as f64,
            back.positions[i][2] as f64,
        );
        assert!((want - got).length() < 1e-5, "Gaussian {i}");
        let want = m * covariance(&source, i) * m.transpose();
        let rel = max_abs(want - covariance(&back, i)) / max_abs(want);
        assert!(rel < 1e-5, "Gaussian {i}: covariance off by {rel:e}");
    }
    // A sheared matrix is refused, naming the problem.
    matrix[4] = 0.7;
    doc["nodes"][0]["matrix"] = json!(matrix);
    let e = parse(&glb_pack(&doc, &bin)).unwrap_err();
    assert!(e.contains("shear"), "{e}");
}

#[test]
fn several_splat_primitives_merge_at_the_highest_degree() {
    let a = small(1, 1);
    let b = small(3, 2);
    let (doc_a, bin_a) = glb_parts(&gltf_write::to_glb(&a).unwrap());
    let (doc_b, bin_b) = glb_parts(&gltf_write::to_glb(&b).unwrap());
    // One buffer: b's views shifted after a's; two meshes, each on its own node, one of
    // them instanced twice (the second copy moved by 10 along x).
    let mut doc = doc_a.clone();
    let views_a = doc_a["bufferViews"].as_array().unwrap().len();
    let accs_a = doc_a["accessors"].as_array().unwrap().len();
    let mut bin = bin_a.clone();
    for v in doc_b["bufferViews"].as_array().unwrap() {
        let mut v = v.clone();
        v["byteOffset"] = json!(v["byteOffset"].as_u64().unwrap() + bin_a.len() as u64);
        doc["bufferViews"].as_array_mut().unwrap().push(v);
    }
    bin.extend(&bin_b);
    for acc in doc_b["accessors"].as_array().unwrap() {
        let mut acc = acc.clone();
        acc["bufferView"] = json!(acc["bufferView"].as_u64().unwrap() + views_a as u64);
        doc["accessors"].as_array_mut().unwrap().push(acc);
    }
    let mut prim = doc_b["meshes"][0]["primitives"][0].clone();
    for (_, v) in prim["attributes"].as_object_mut().unwrap() {
        *v = json!(v.as_u64().unwrap() + accs_a as u64);
    }
    doc["meshes"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "primitives": [prim] }));
    doc["buffers"][0]["byteLength"] = json!(bin.len());
    doc["nodes"] =
        json!([{ "mesh": 0 }, { "mesh": 1 }, { "mesh": 1, "translation": [-10.0, 0.0, 0.0] }]);
    doc["scenes"][0]["nodes"] = json!([0, 1, 2]);
    let (back, format) = parse(&glb_pack(&doc, &bin)).unwrap();
    assert!(
        matches!(format, SceneFormat::Gltf(i) if i.primitives == 3),
        "{format}"
    );
    assert!(
        format.to_string().contains("3 splat primitives merged"),
        "{format}"
    );
    assert_eq!(back.len(), a.len() + 2 * b.len());
    assert_eq!(back.sh_degree, 3);
    let k = back.sh_stride();
    for i in 0..a.len() {
        assert_eq!(
            &back.sh[i * k..i * k + a.sh_stride()],
            &a.sh[i * a.sh_stride()..(i + 1) * a.sh_stride()]
        );
        assert!(back.sh[i * k + a.sh_stride()..(i + 1) * k]
            .iter()
            .all(|&v| v == 0.0));
    }
    for i in 0..b.len() {
        let j = a.len() + b.len() + i;
        // -10 along glTF's x is +10 along ours.
        assert!((back.positions[j][0] - (b.positions[i][0] + 10.0)).abs() < 1e-5);
        assert_eq!(&back.sh[j * k..(j + 1) * k], &b.sh[i * k..(i + 1) * k]);
    }
}

#[test]
fn quantised_and_interleaved_attributes_are_dequantised_as_gltf_defines() {
    // One Gaussian's attributes, written by hand: POSITION as normalised shorts
    // (KHR_mesh_quantization), ROTATION as normalised bytes, SCALE as unsigned shorts,
    // OPACITY as a normalised byte, the DC as floats, all in one interleaved view.
    let mut bin = Vec::new();
    bin.extend(16384i16.to_le_bytes()); // x = 16384 / 32767
    bin.extend((-32767i16).to_le_bytes()); // y = -1
    bin.extend(0i16.to_le_bytes());
    bin.extend([0u8, 0]); // pad to 8
    bin.extend([0i8 as u8, 0, 127, 127]); // rotation (0, 0, 1, 1) / sqrt 2 after normalising
    bin.extend(2u16.to_le_bytes()); // scale 2, 3, 4 (plain integers)
    bin.extend(3u16.to_le_bytes());
    bin.extend(4u16.to_le_bytes());
    bin.extend([51u8, 0]); // opacity 51 / 255 = 0.2
    for v in [0.1f32, -0.2, 0.3] {
        bin.extend(v.to_le_bytes());
    }
    let stride = bin.len();
    let acc = |offset: usize, component: u32, kind: &str, normalized: bool| {
        json!({ "bufferView": 0, "byteOffset": offset, "componentType": component,
                "count": 1, "type": kind, "normalized": normalized })
    };
    let doc = json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["KHR_gaussian_splatting", "KHR_mesh_quantization"],
        "extensionsRequired": ["KHR_mesh_quantization"],
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": [{ "buffer": 0, "byteLength": bin.len(), "byteStride": stride }],
        "accessors": [
            acc(0, 5122, "VEC3", true),
            acc(8, 5120, "VEC4", true),
            acc(12, 5123, "VEC3", false),
            acc(18, 5121, "SCALAR", true),
            acc(20, 5126, "VEC3", false),
        ],
        "meshes": [{ "primitives": [{ "mode": 0, "attributes": {
            "POSITION": 0, "KHR_gaussian_splatting:ROTATION": 1, "KHR_gaussian_splatting:SCALE": 2,
            "KHR_gaussian_splatting:OPACITY": 3, "KHR_gaussian_splatting:SH_DEGREE_0_COEF_0": 4 },
            "extensions": { "KHR_gaussian_splatting": { "kernel": "ellipse", "colorSpace": "srgb_rec709_display" } } }] }],
        "nodes": [{ "mesh": 0 }],
        "scenes": [{ "nodes": [0] }],
    });
    let (s, _) = parse(&glb_pack(&doc, &bin)).unwrap();
    assert_eq!(s.len(), 1);
    // Back in our frame: (-x, -y, z).
    assert_eq!(s.positions[0], [-(16384.0f32 / 32767.0), 1.0, 0.0]);
    for (k, want) in [2.0f32, 3.0, 4.0].iter().enumerate() {
        assert!((s.log_scales[0][k] - want.ln()).abs() < 1e-6);
    }
    assert!((scene::sigmoid(s.opacity_logits[0]) - 0.2).abs() < 1e-6);
    // The half turn about z maps the rotation (0, 0, 1, 1)/sqrt 2 (x y z w) to ...
    let g = DQuat::from_xyzw(0.0, 0.0, 1.0, 1.0).normalize();
    let want = DQuat::from_rotation_z(std::f64::consts::PI) * g;
    let [w, x, y, z] = s.rotations[0];
    let got = DQuat::from_xyzw(x as f64, y as f64, z as f64, w as f64).normalize();
    assert!(want.dot(got).abs() > 1.0 - 1e-6, "{want:?} vs {got:?}");
    assert_eq!(&s.sh[..3], &[0.1, -0.2, 0.3]);
}

#[test]
fn the_spz_compressed_variant_reads_its_payload() {
    let source = common::shared_scene("playbot_lod6_1873_sh2.ply");
    let payload = spz::to_bytes_v3(&source).unwrap();
    let (want, _, _) = spz::parse(&payload, Path::new("p.spz")).unwrap();
    let (mut doc, _) = glb_parts(&gltf_write::to_glb(&source).unwrap());
    // The accessors keep their descriptions but lose their data: the payload has it.
    for acc in doc["accessors"].as_array_mut().unwrap() {
        acc.as_object_mut().unwrap().remove("bufferView");
    }
    doc["bufferViews"] = json!([{ "buffer": 0, "byteLength": payload.len() }]);
    doc["buffers"] = json!([{ "byteLength": payload.len() }]);
    doc["meshes"][0]["primitives"][0]["extensions"]["KHR_gaussian_splatting"]["extensions"] =
        json!({ "KHR_gaussian_splatting_compression_spz_2": { "bufferView": 0 } });
    doc["extensionsUsed"] = json!([
        "KHR_gaussian_splatting",
        "KHR_gaussian_splatting_compression_spz_2"
    ]);
    doc["extensionsRequired"] = json!(["KHR_gaussian_splatting_compression_spz_2"]);
    let (back, format) = parse(&glb_pack(&doc, &payload)).unwrap();
    assert!(format.to_string().contains("SPZ-compressed"), "{format}");
    // The payload's Gaussians as SPZ decodes them, exactly (two half turns cancel).
    assert_eq!(back.positions, want.positions);
    assert_eq!(back.sh, want.sh);
    assert_eq!(back.opacity_logits, want.opacity_logits);
}

#[test]
fn a_gltf_with_a_data_uri_or_a_bin_beside_it_loads() {
    let source = small(2, 5);
    let (mut doc, bin) = glb_parts(&gltf_write::to_glb(&source).unwrap());
    let dir = tempfile::tempdir().unwrap();
    doc["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        data_encoding::BASE64.encode(&bin)
    ));
    let embedded = dir.path().join("embedded.gltf");
    std::fs::write(&embedded, serde_json::to_vec(&doc).unwrap()).unwrap();
    let (a, format) = io::scene::load_with_format(&embedded).unwrap();
    assert!(
        matches!(format, SceneFormat::Gltf(i) if !i.binary),
        "{format}"
    );
    let (gltf, bin2) = gltf_write::to_gltf(&source, "my scene.bin").unwrap();
    std::fs::write(dir.path().join("my scene.bin"), bin2).unwrap();
    let beside = dir.path().join("beside.gltf");
    std::fs::write(&beside, &gltf).unwrap();
    assert!(String::from_utf8_lossy(&gltf).contains("my%20scene.bin"));
    let b = io::scene::load(&beside).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.positions, source.positions);
    // Its buffer file missing: an error naming the .gltf, the file it names and why.
    std::fs::remove_file(dir.path().join("my scene.bin")).unwrap();
    let e = io::scene::load(&beside).unwrap_err().to_string();
    assert!(
        e.starts_with(&format!("{}: ", beside.display()))
            && e.contains("buffer 0 is the file")
            && e.contains("my scene.bin")
            && e.contains("cannot be read"),
        "{e}"
    );
}

/// What `verisplat info` says of a `.gltf` whose `.bin` is missing and of a GLB cut short
/// (issue 59, item 11): one sentence naming the file given, and for the `.gltf` the file
/// it names too.
#[test]
fn info_names_the_gltf_and_its_missing_bin_and_a_truncated_glb() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad");
    std::fs::create_dir(&bad).unwrap();
    let (gltf, _) = gltf_write::to_gltf(&small(1, 2), "nobin.bin").unwrap();
    let nobin = bad.join("nobin.gltf");
    std::fs::write(&nobin, gltf).unwrap();
    let e = crate::common::cli::fails(&["info", nobin.to_str().unwrap()], &bad.join("none"));
    assert!(
        e.contains("nobin.gltf: buffer 0 is the file") && e.contains("nobin.bin"),
        "{e}"
    );
    let glb = gltf_write::to_glb(&small(1, 2)).unwrap();
    for cut in [10, 12, 19] {
        let short = bad.join(format!("short{cut}.glb"));
        std::fs::write(&short, &glb[..cut]).unwrap();
        let e = crate::common::cli::fails(&["info", short.to_str().unwrap()], &bad.join("none"));
        assert!(
            e.contains(&format!("short{cut}.glb: is a truncated GLB: {cut} bytes")),
            "{e}"
        );
    }
}

/// A change to a glTF document.
type Edit = Box<dyn Fn(&mut Value)>;

#[test]
fn broken_files_get_clear_errors_never_panics() {
    let source = small(2, 3);
    let glb = gltf_write::to_glb(&source).unwrap();
    let (doc, bin) = glb_parts(&glb);
    let edit = |f: &dyn Fn(&mut Value)| -> String {
        let mut d = doc.clone();
        f(&mut d);
        parse(&glb_pack(&d, &bin)).unwrap_err()
    };
    let attrs = "/meshes/0/primitives/0/attributes";
    let cases: Vec<(&str, Edit)> = vec![
        (
            "has no KHR_gaussian_splatting:SCALE",
            Box::new(move |d| {
                d.pointer_mut(attrs)
                    .unwrap()
                    .as_object_mut()
                    .unwrap()
                    .remove("KHR_gaussian_splatting:SCALE");
            }),
        ),
        (
            "2 of the 3 SH degree-1",
            Box::new(move |d| {
                d.pointer_mut(attrs)
                    .unwrap()
                    .as_object_mut()
                    .unwrap()
                    .remove("KHR_gaussian_splatting:SH_DEGREE_1_COEF_2");
            }),
        ),
        (
            "requires the glTF extension EXT_foo",
            Box::new(|d| d["extensionsRequired"] = json!(["EXT_foo"])),
        ),
        (
            "EXT_meshopt_compression",
            Box::new(|d| {
                d["bufferViews"][0]["extensions"] = json!({"EXT_meshopt_compression": {}})
            }),
        ),
        (
            "deeper than",
            Box::new(|d| d["nodes"] = json!([{ "mesh": 0, "children": [0] }])),
        ),
        (
            "mode 4",
            Box::new(|d| d["meshes"][0]["primitives"][0]["mode"] = json!(4)),
        ),
        (
            "holds no Gaussian splats",
            Box::new(|d| {
                d["meshes"][0]["primitives"][0]
                    .as_object_mut()
                    .unwrap()
                    .remove("extensions");
            }),
        ),
        (
            "run past the end",
            Box::new(|d| d["accessors"][0]["count"] = json!(1_000_000)),
        ),
        (
            "kernel \"gaussian3\"",
            Box::new(|d| {
                d["meshes"][0]["primitives"][0]["extensions"]["KHR_gaussian_splatting"]["kernel"] =
                    json!("gaussian3");
            }),
        ),
    ];
    for (want, f) in cases {
        let e = edit(&*f);
        assert!(
            e.contains("t.glb") && e.contains(want),
            "want {want:?}, got {e}"
        );
    }
    // Out-of-range values, written into the buffer.
    let opacity_view = doc["accessors"][doc.pointer(attrs).unwrap()
        ["KHR_gaussian_splatting:OPACITY"]
        .as_u64()
        .unwrap() as usize]["bufferView"]
        .as_u64()
        .unwrap() as usize;
    let off = doc["bufferViews"][opacity_view]["byteOffset"]
        .as_u64()
        .unwrap() as usize;
    let mut bad = bin.clone();
    bad[off..off + 4].copy_from_slice(&1.5f32.to_le_bytes());
    let e = parse(&glb_pack(&doc, &bad)).unwrap_err();
    assert!(e.contains("opacity 1.5"), "{e}");
    // Truncations and corrupted bytes anywhere: an error or a scene, never a panic.
    for cut in (0..glb.len()).step_by(97) {
        let _ = parse(&glb[..cut]);
    }
    let mut seed = 0x9e37_79b9u32;
    for _ in 0..200 {
        let mut g = glb.clone();
        for _ in 0..4 {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            let k = seed as usize % g.len();
            g[k] ^= (seed >> 24) as u8 | 1;
        }
        let _ = parse(&g);
    }
    assert!(parse(&glb[..glb.len() - 10])
        .unwrap_err()
        .contains("truncated"));
    // Cut inside the header or before the JSON chunk's header: truncated, not "no JSON".
    for cut in [4, 10, 12, 19] {
        let e = parse(&glb[..cut]).unwrap_err();
        assert!(e.contains("t.glb: is a truncated GLB"), "{cut}: {e}");
    }
}

#[test]
fn convert_writes_a_gltf_with_its_bin_and_never_overwrites_either() {
    use verisplat::io::scene::write::{self, ConvertOptions, OutputFormat};
    let src = common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("robot.gltf");
    let report = write::convert(&src, &out, &ConvertOptions::default()).unwrap();
    assert_eq!(report.output_format, OutputFormat::Gltf);
    assert!(dir.path().join("robot.bin").is_file());
    let back = io::scene::load(&out).unwrap();
    assert_eq!(
        back.positions,
        common::shared_scene("playbot_lod6_1873_sh2.ply").positions
    );
    let e = write::convert(&src, &out, &ConvertOptions::default()).unwrap_err();
    assert!(e.to_string().contains("robot.gltf"), "{e}");
    // A .bin already there (from another file) is not replaced, and no .gltf appears.
    let other = dir.path().join("other.gltf");
    std::fs::write(dir.path().join("other.bin"), b"mine").unwrap();
    let e = write::convert(&src, &other, &ConvertOptions::default()).unwrap_err();
    assert!(e.to_string().contains("other.bin"), "{e}");
    assert!(!other.exists());
    assert_eq!(
        std::fs::read(dir.path().join("other.bin")).unwrap(),
        b"mine"
    );
    // --overwrite replaces both; a .glb is one file.
    let opts = ConvertOptions {
        overwrite: true,
        ..Default::default()
    };
    write::convert(&src, &other, &opts).unwrap();
    assert_eq!(io::scene::load(&other).unwrap().len(), 1873);
    let glb = dir.path().join("robot.glb");
    write::convert(&src, &glb, &ConvertOptions::default()).unwrap();
    assert!(
        matches!(io::scene::load_with_format(&glb).unwrap().1, SceneFormat::Gltf(i) if i.binary)
    );
}
