//! Masks (`verisplat::train::masks`): where they are read from (`masks/` beside `images/`,
//! a transforms frame's `mask_path`, an RGBA photo's alpha with `--alpha-mode`), scaled
//! with their photo under `-r`; bad masks as one sentence each; a masked pixel adds
//! nothing to the loss and its gradient, on the device as in the f64 reference, so a
//! Gaussian seen only there gets no gradient; a masked run steps on the device as on the
//! host; and a mask over an occluder painted on every training view lifts the held-out
//! PSNR.

use super::training::{assert_groups_agree, device_vs_host_options, model_ply, Harness};
use crate::common::cli::verisplat;
use crate::common::dataset::make_dataset;
use std::path::Path;
use verisplat::train::data::{self, LoadOptions, Resolution};
use verisplat::train::masks::AlphaMode;

/// Writes a grey PNG of `w x h` whose pixel (x, y) is `value(x, y)`.
fn grey_png(path: &Path, w: u32, h: u32, value: impl Fn(u32, u32) -> u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::GrayImage::from_fn(w, h, |x, y| image::Luma([value(x, y)]))
        .save(path)
        .unwrap();
}

/// Black (ignored) left of `edge`, white right of it.
fn left_black(edge: u32) -> impl Fn(u32, u32) -> u8 {
    move |x, _| if x < edge { 0 } else { 255 }
}

/// The flags of a view's mask as `false` left of `edge` and `true` right of it?
fn is_left_masked(v: &data::View, edge: u32) -> bool {
    let w = v.camera.width as usize;
    let m = v.mask.as_ref().expect("a mask");
    m.len() == w * v.camera.height as usize
        && m.iter()
            .enumerate()
            .all(|(i, &k)| k == ((i % w) as u32 >= edge))
}

/// `masks/` beside `images/`: a mask per photo with its stem and any extension (grey,
/// RGB, RGBA, 1-bit, 16-bit, COLMAP's NAME.png.png), scaled with the photo under `-r` (the same area
/// average, then thresholded), or given at the `-r` size already; without `masks/` no
/// view has a mask and the photos are as before.
#[test]
fn a_masks_folder_beside_the_images_is_read_and_scaled_with_the_photos() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("data");
    make_dataset(&set, 4, 32, 24);
    let before = data::load_colmap(&set, Resolution(2), false).unwrap();
    assert!(before.train.iter().all(|v| v.mask.is_none()));
    let masks = set.join("masks");
    grey_png(&masks.join("view_000.png"), 32, 24, left_black(8));
    grey_png(&masks.join("view_001.png.png"), 32, 24, left_black(8));
    // RGB, under another extension (the format is read from the bytes).
    image::RgbImage::from_fn(32, 24, |x, _| image::Rgb([if x < 8 { 0 } else { 255 }; 3]))
        .save(masks.join("view_002.png"))
        .unwrap();
    std::fs::rename(masks.join("view_002.png"), masks.join("view_002.tif")).unwrap();
    // RGBA: a transparent pixel is masked too.
    image::RgbaImage::from_fn(32, 24, |x, _| {
        image::Rgba([255, 255, 255, if x < 8 { 0 } else { 255 }])
    })
    .save(masks.join("view_003.png"))
    .unwrap();
    let after = data::load(&set, &LoadOptions::new(Resolution(2), false)).unwrap();
    for (v, b) in after.train.iter().zip(&before.train) {
        assert_eq!((v.camera.width, v.camera.height), (16, 12));
        assert!(is_left_masked(v, 4), "{}", v.camera.name);
        assert_eq!(v.image, b.image, "the photo is as without masks");
    }
    // A 1-bit and a 16-bit grey PNG (made with Pillow, kept beside this file).
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/all/train/mask_fixtures");
    std::fs::copy(fixtures.join("left8_1bit.png"), masks.join("view_000.png")).unwrap();
    std::fs::remove_file(masks.join("view_001.png.png")).unwrap();
    std::fs::copy(fixtures.join("left8_16bit.png"), masks.join("view_001.png")).unwrap();
    let bits = data::load(&set, &LoadOptions::new(Resolution(2), false)).unwrap();
    assert!(is_left_masked(&bits.train[0], 4) && is_left_masked(&bits.train[1], 4));
    // A mask at the -r size is used as it is.
    grey_png(&masks.join("view_000.png"), 16, 12, left_black(5));
    let at_r = data::load(&set, &LoadOptions::new(Resolution(2), false)).unwrap();
    assert!(is_left_masked(&at_r.train[0], 5));
}

/// A transforms frame's `mask_path` (relative to the transforms file's folder) is its
/// mask, and a transforms data set's RGBA photos keep their default (composited onto
/// the background) unless `--alpha-mode` says otherwise.
#[test]
fn a_frames_mask_path_and_the_alpha_modes_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path();
    // RGBA photos: red, transparent left of x = 6.
    let frames: Vec<serde_json::Value> = (0..3)
        .map(|i| {
            std::fs::create_dir_all(set.join("images")).unwrap();
            image::RgbaImage::from_fn(24, 16, |x, _| {
                image::Rgba([255, 0, 0, if x < 6 { 0 } else { 255 }])
            })
            .save(set.join(format!("images/f{i}.png")))
            .unwrap();
            grey_png(&set.join(format!("m/f{i}_mask.png")), 24, 16, |x, _| {
                if x >= 18 {
                    0
                } else {
                    255
                }
            });
            serde_json::json!({
                "file_path": format!("images/f{i}.png"),
                "mask_path": format!("m/f{i}_mask.png"),
                "transform_matrix": [[1.0, 0.0, 0.0, i as f64], [0.0, 1.0, 0.0, 0.0],
                                     [0.0, 0.0, 1.0, 3.0], [0.0, 0.0, 0.0, 1.0]],
            })
        })
        .collect();
    let doc = serde_json::json!({ "camera_angle_x": 0.8, "frames": frames });
    std::fs::write(set.join("transforms.json"), doc.to_string()).unwrap();
    let load = |alpha: Option<AlphaMode>| {
        let opts = LoadOptions {
            background: [0.0, 0.0, 1.0],
            alpha,
            ..LoadOptions::new(Resolution(1), false)
        };
        data::load(set, &opts).unwrap()
    };
    let right_masked = |v: &data::View, keep_left: bool| {
        let m = v.mask.as_ref().expect("a mask");
        m.iter().enumerate().all(|(i, &k)| {
            let x = i % 24;
            k == (x < 18 && (keep_left || x >= 6))
        })
    };
    // The default: composited onto the (blue) background; the mask_path's mask.
    let default = load(None);
    let v = &default.train[0];
    assert!(right_masked(v, true));
    assert_eq!(
        (v.image[0], v.image[10]),
        ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    );
    assert_eq!(load(Some(AlphaMode::Background)).train[0].image, v.image);
    // ignore: the colour as stored.
    let ignore = load(Some(AlphaMode::Ignore));
    assert_eq!(ignore.train[0].image[0], [1.0, 0.0, 0.0]);
    assert!(right_masked(&ignore.train[0], true));
    // mask: alpha below 0.5 is masked too (and the colour is as stored).
    let mask = load(Some(AlphaMode::Mask));
    assert!(right_masked(&mask.train[0], false));
    assert_eq!(mask.train[0].image[0], [1.0, 0.0, 0.0]);
    // A frame without a mask_path where the others have one: one sentence naming its
    // photo.
    let mut doc = doc;
    doc["frames"][1]
        .as_object_mut()
        .unwrap()
        .remove("mask_path");
    std::fs::write(set.join("transforms.json"), doc.to_string()).unwrap();
    let e = data::load(set, &LoadOptions::new(Resolution(1), false))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("images/f1.png") && e.contains("has no mask") && e.contains("2 other"),
        "{e}"
    );
    // A COLMAP data set drops alpha by default; --alpha-mode mask masks with it.
    let colmap = tempfile::tempdir().unwrap();
    make_dataset(colmap.path(), 2, 24, 16);
    for i in 0..2 {
        std::fs::copy(
            set.join(format!("images/f{i}.png")),
            colmap.path().join(format!("images/view_00{i}.png")),
        )
        .unwrap();
    }
    let plain = data::load(colmap.path(), &LoadOptions::new(Resolution(1), false)).unwrap();
    assert!(plain.train[0].mask.is_none());
    assert_eq!(plain.train[0].image[0], [1.0, 0.0, 0.0]);
    let opts = LoadOptions {
        alpha: Some(AlphaMode::Mask),
        ..LoadOptions::new(Resolution(1), false)
    };
    let masked = data::load(colmap.path(), &opts).unwrap();
    assert!(is_left_masked(&masked.train[0], 6));
}

/// Bad masks: each one sentence naming the file, a non-zero exit, no panic, nothing
/// written.
#[test]
fn bad_masks_give_one_sentence_each() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("data");
    make_dataset(&set, 4, 32, 24);
    let masks = set.join("masks");
    for i in 0..4 {
        grey_png(
            &masks.join(format!("view_00{i}.png")),
            32,
            24,
            left_black(8),
        );
    }
    let model = dir.path().join("model");
    let fails_with = |what: &str, says: &[&str]| {
        let o = verisplat(&[
            "train",
            set.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--iterations",
            "5",
            "-r",
            "2",
            "-q",
        ]);
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(!o.status.success(), "{what}: succeeded");
        assert!(!err.contains("panicked"), "{what}: {err}");
        for s in says {
            assert!(err.contains(s), "{what}: {err}");
        }
        assert_eq!(err.lines().count(), 1, "{what}: {err}");
        assert!(!model.exists(), "{what}: wrote {}", model.display());
    };
    let one = masks.join("view_001.png");
    grey_png(&one, 10, 10, left_black(3));
    fails_with(
        "a mask of another size",
        &["view_001.png", "10x10", "32x24", "16x12"],
    );
    std::fs::remove_file(&one).unwrap();
    fails_with(
        "a photo without its mask",
        &["images/view_001.png", "no mask", "3 other photo(s)"],
    );
    std::fs::write(&one, b"not a PNG").unwrap();
    fails_with(
        "an unreadable mask",
        &["masks/view_001.png", "cannot be read as a mask"],
    );
    grey_png(&one, 32, 24, |_, _| 0);
    fails_with("a mask of nothing", &["masks/view_001.png", "every pixel"]);
    // Good masks: the run says what they ignore.
    grey_png(&one, 32, 24, left_black(8));
    let o = verisplat(&[
        "train",
        set.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
        "--iterations",
        "5",
        "-r",
        "2",
    ]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("4 of 4 views masked (25.0 % of their pixels ignored"),
        "{err}"
    );
}

/// A Gaussian whose footprint lies wholly in the masked part of a view gets no gradient
/// in any group (and adds nothing to the densification statistics, its screen-space
/// gradients being zero), while those in the kept part get theirs: the device's loss
/// gradient through the device's backward pass.
#[test]
fn a_gaussian_seen_only_through_masked_pixels_gets_no_gradient() {
    use verisplat::core::model::grad::PixelGrads;
    use verisplat::render::backward::differentiable::DiffRasterizer;
    let cam = super::gradients::grad_camera();
    let (w, h) = (cam.width as usize, cam.height as usize);
    let p = super::gradients::grad_scene(80, 9, Some(1), 0);
    let renderer = crate::common::gpu::new_renderer(None);
    let mut loss = verisplat::train::loss::GpuLoss::new(renderer.ctx()).unwrap();
    let mut rast = DiffRasterizer::with_renderer(renderer);
    let opts = verisplat::cpu::RenderOptions::default();
    let (frame, token) = rast.forward(&p, &cam, &opts).unwrap();
    let splats = rast.projected().unwrap();
    let target: Vec<[f32; 3]> = frame
        .color
        .iter()
        .map(|c| [1.0 - c[0], 0.5 * c[1], 0.3])
        .collect();
    let edge = 28.0f32;
    let keep: Vec<bool> = (0..w * h).map(|i| (i % w) as f32 >= edge).collect();
    let ctx = rast.renderer().ctx();
    let (_, g) = loss
        .compute_masked(
            ctx,
            &frame.color,
            &target,
            Some(&keep),
            w as u32,
            h as u32,
            verisplat::train::loss::LAMBDA_DSSIM,
        )
        .unwrap();
    let pixel_grads = PixelGrads {
        color: g.iter().flatten().copied().collect(),
        alpha: Vec::new(),
        depth: Vec::new(),
    };
    let grads = rast.backward(&p, &cam, &opts, token, &pixel_grads).unwrap();
    let stride = grads.colors.len() / splats.len();
    let (mut hidden, mut seen) = (0, 0);
    for (i, s) in splats.iter().enumerate() {
        let r = s.color_radius[3];
        let x = s.mean_opacity_bound[0];
        let values: Vec<f32> = grads.means[i]
            .iter()
            .chain(&grads.quats[i])
            .chain(&grads.scales[i])
            .chain(&[grads.opacities[i]])
            .chain(&grads.colors[i * stride..(i + 1) * stride])
            .chain(&grads.means2d[i])
            .chain(&grads.absgrad[i])
            .copied()
            .collect();
        if r > 0.0 && x + r + 2.0 < edge {
            hidden += 1;
            assert!(
                values.iter().all(|&v| v == 0.0),
                "Gaussian {i} at x {x} radius {r}: {values:?}"
            );
        } else if r > 0.0 && x > edge && values.iter().any(|&v| v != 0.0) {
            seen += 1;
        }
    }
    eprintln!("{hidden} Gaussians wholly masked, {seen} kept with gradients");
    assert!(hidden >= 3 && seen >= 3, "{hidden} masked, {seen} kept");
    crate::common::gpu::assert_validation_clean(rast.renderer());
}

/// The training views masked (their lower left quarter): the state on the device steps
/// as the host optimiser does (30 iterations; each iteration's loss within 1e-4, the
/// groups as below); a mask that keeps every pixel writes the bytes of no mask (the
/// unmasked arithmetic is untouched); and validation stays quiet.
#[test]
fn a_masked_run_steps_on_the_device_as_on_the_host() {
    let mut h = Harness::new(8, 64, 48, None);
    let opts = device_vs_host_options();
    let (_, plain) = model_ply(&h.train("plain", &opts, false).2);
    for v in &mut h.dataset.train {
        v.mask = Some(vec![true; 64 * 48]);
    }
    let (_, all_kept) = model_ply(&h.train("all-kept", &opts, false).2);
    assert!(
        plain == all_kept,
        "a mask keeping every pixel changed the model"
    );
    for v in &mut h.dataset.train {
        v.mask = Some(
            (0..64 * 48)
                .map(|i| !((i % 64) < 32 && i / 64 >= 24))
                .collect(),
        );
    }
    let (_, dev_losses, at) = h.train("device", &opts, false);
    let (dev, dev_bytes) = model_ply(&at);
    let (_, host_losses, at) = h.train("host", &opts, true);
    let (host, _) = model_ply(&at);
    let worst = dev_losses
        .iter()
        .zip(&host_losses)
        .map(|(a, b)| ((a - b) / b).abs())
        .fold(0.0, f64::max);
    eprintln!("largest relative loss difference per iteration: {worst:.2e}");
    assert!(worst < 1e-4, "{worst}");
    assert!(dev_bytes != plain, "the mask changed nothing");
    // Every group but the quaternions as close as unmasked runs are; the quaternions of
    // the near-isotropic Gaussians the points start as have gradients of rounding noise
    // (their rotation changes nothing), which Adam turns into steps of the learning rate
    // (1e-3) of either sign: measured 1.9e-4, six Gaussians one step apart.
    assert_groups_agree(&dev, &host, 1e-3);
    let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    for (name, a, b) in [
        ("centres", flat(&dev.positions), flat(&host.positions)),
        ("log scales", flat(&dev.log_scales), flat(&host.log_scales)),
        ("opacity logits", dev.opacity_logits, host.opacity_logits),
        ("SH", dev.sh, host.sh),
    ] {
        let rel = verisplat::core::model::grad::relative_l2(
            &a.iter().map(|&x| x as f64).collect::<Vec<_>>(),
            &b.iter().map(|&x| x as f64).collect::<Vec<_>>(),
        );
        assert!(rel < 1e-5, "{name}: {rel}");
    }
    h.assert_validation_clean();
}

/// A mask helps: an opaque magenta occluder painted on the same corner (the upper left
/// quarter of the frame) of every training view, and the same training (400 iterations)
/// without and with masks over it; the held-out views (every 8th, clean) score higher
/// with the masks (measured on lavapipe: 27.56 dB without, 32.43 dB with; asserted: by
/// 2 dB).
#[test]
fn masking_an_occluder_lifts_the_held_out_psnr() {
    let mut h = Harness::new(24, 64, 48, None);
    h.dataset = data::load(
        &h.dir.path().join("data"),
        &LoadOptions::new(Resolution(1), true),
    )
    .unwrap();
    let corner = |i: usize| (i % 64) < 32 && i / 64 < 24;
    for v in &mut h.dataset.train {
        for (i, p) in v.image.iter_mut().enumerate() {
            if corner(i) {
                *p = [1.0, 0.0, 1.0];
            }
        }
    }
    let mut opts = device_vs_host_options();
    opts.settings.iterations = 400;
    opts.settings.densify_from_iter = 100;
    opts.settings.densification_interval = 100;
    opts.settings.opacity_reset_interval = 100_000;
    opts.test_iterations = vec![400];
    let psnr = |h: &mut Harness, name: &str| {
        let report = h.train(name, &opts, false).0;
        report.evaluations.last().expect("an evaluation").psnr
    };
    let without = psnr(&mut h, "without");
    for v in &mut h.dataset.train {
        v.mask = Some((0..64 * 48).map(|i| !corner(i)).collect());
    }
    let with = psnr(&mut h, "with");
    eprintln!("held-out PSNR: {without:.2} dB without masks, {with:.2} dB with");
    assert!(with > without + 2.0, "{with} vs {without}");
    h.assert_validation_clean();
}

/// A fisheye camera's pixels outside its image circle (past the field of view its
/// polynomial images: k1 = -0.5 stops growing at 0.82 rad) are masked without any mask
/// file: the corners are, the middle is not; a pinhole's view has no mask.
#[test]
fn a_fisheyes_pixels_outside_its_image_circle_are_masked() {
    let dir = tempfile::tempdir().unwrap();
    make_dataset(dir.path(), 2, 64, 48);
    let cameras = dir.path().join("sparse/0/cameras.txt");
    let text = std::fs::read_to_string(&cameras).unwrap();
    let fisheye: Vec<String> = text
        .lines()
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            if l.starts_with('#') || f.len() != 8 {
                return l.to_string();
            }
            format!(
                "{} OPENCV_FISHEYE {} {} 30 30 {} {} -0.5 0 0 0",
                f[0], f[2], f[3], f[6], f[7]
            )
        })
        .collect();
    std::fs::write(&cameras, fisheye.join("\n") + "\n").unwrap();
    let set = data::load(dir.path(), &LoadOptions::new(Resolution(1), false)).unwrap();
    for v in &set.train {
        let m = v.mask.as_ref().expect("the image circle's mask");
        assert!(!m[0] && !m[63] && !m[64 * 47], "the corners are masked");
        assert!(m[24 * 64 + 32], "the middle is kept");
        let kept = m.iter().filter(|&&k| k).count();
        eprintln!(
            "{}: {kept} of {} pixels inside the circle",
            v.camera.name,
            m.len()
        );
    }
}

/// `eval` with a `masks/` folder beside `--images`: only the unmasked pixels are scored
/// (an occluder painted on a photo and masked costs nothing: the PSNR is that of the
/// clean photo's kept pixels), the output says so and the report marks the rows; without
/// the folder the occluder is scored.
#[test]
fn eval_scores_only_the_unmasked_pixels_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let set = dir.path().join("data");
    make_dataset(&set, 2, 32, 24);
    let photo = set.join("images/view_000.png");
    let mut img = image::open(&photo).unwrap().to_rgb8();
    for y in 0..12 {
        for x in 0..16 {
            img.put_pixel(x, y, image::Rgb([255, 0, 255]));
        }
    }
    img.save(&photo).unwrap();
    let scene = crate::common::shared_data().join("playbot_lod6_1873_sh2.ply");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let run = |out: &str| {
        verisplat(&[
            "eval",
            &s(&scene),
            "--cameras",
            &s(&set.join("sparse/0")),
            "--images",
            &s(&set.join("images")),
            "--split",
            "all",
            "-o",
            &s(&dir.path().join(out)),
        ])
    };
    let eval = |out: &str| {
        let rep = dir.path().join(out);
        let o = run(out);
        let (out, err) = (
            String::from_utf8_lossy(&o.stdout).to_string(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        );
        assert!(o.status.success(), "{err}");
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(rep.join("report.json")).unwrap())
                .unwrap();
        let psnr = json["results"][0]["psnr"].as_f64().unwrap_or(f64::INFINITY);
        (out, json, psnr)
    };
    let (out, _, unmasked) = eval("plain");
    assert!(!out.contains("unmasked"), "{out}");
    let masks = set.join("masks");
    for i in 0..2 {
        grey_png(&masks.join(format!("view_00{i}.png")), 32, 24, |x, y| {
            if x < 16 && y < 12 {
                0
            } else {
                255
            }
        });
    }
    let (out, json, masked) = eval("masked");
    eprintln!("view_000: {unmasked:.2} dB scoring the occluder, {masked:.2} dB masked");
    assert!(
        out.contains("scored only the unmasked pixels of 2 photo(s)"),
        "{out}"
    );
    assert_eq!(json["results"][0]["masked"], serde_json::json!(true));
    assert!(unmasked < 15.0, "{unmasked}");
    assert!(masked > 35.0, "{masked}");

    // The same masks named by the frames' mask_path of the data set's transforms file.
    std::fs::rename(&masks, set.join("frame_masks")).unwrap();
    let frames = |last_mask: bool| {
        let frame = |i: usize| {
            let mut f = serde_json::json!({"file_path": format!("images/view_00{i}")});
            if i == 0 || last_mask {
                f["mask_path"] = format!("frame_masks/view_00{i}.png").into();
            }
            f
        };
        let doc = serde_json::json!({"frames": [frame(0), frame(1)]});
        std::fs::write(set.join("transforms.json"), doc.to_string()).unwrap();
    };
    frames(true);
    let (out, json, by_path) = eval("mask_path");
    assert!(
        out.contains("scored only the unmasked pixels of 2 photo(s)"),
        "{out}"
    );
    assert_eq!(json["results"][0]["masked"], serde_json::json!(true));
    assert_eq!(by_path, masked);
    // A frame without its mask_path where the other has one: one sentence naming the photo.
    frames(false);
    let o = run("missing");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("view_001.png: has no mask_path in") && err.contains("transforms.json"),
        "{err}"
    );
}
