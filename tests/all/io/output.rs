//! PNG and EXR writers: values read back equal the frame; writes are atomic and never
//! replace an existing file unasked.

use verisplat::core::frame::Frame;
use verisplat::io::output::{self, ImageFormat, OutputError};

fn test_frame() -> Frame {
    let (w, h) = (37u32, 21u32);
    let mut f = Frame::background(w, h, [0.0; 3]);
    for y in 0..h {
        for x in 0..w {
            let i = f.index(x, y);
            f.color[i] = [
                x as f32 / w as f32,
                y as f32 / h as f32,
                1.5 - (x + y) as f32 / 40.0,
            ];
            f.alpha[i] = ((x * y) % 7) as f32 / 6.0;
            f.depth[i] = if f.alpha[i] > 0.0 {
                1.0 + x as f32 * 0.25
            } else {
                0.0
            };
        }
    }
    f
}

#[test]
fn exr_has_rgbaz_channels_equal_to_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.exr");
    let f = test_frame();
    output::write_frame(&f, &path, ImageFormat::Exr, false).unwrap();
    let image = exr::prelude::read_all_flat_layers_from_file(&path).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!(layer.size.width(), f.width as usize);
    assert_eq!(layer.size.height(), f.height as usize);
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    assert_eq!(names, ["A", "B", "G", "R", "Z"]);
    let plane = |name: &str| -> Vec<f32> {
        let ch = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap();
        match &ch.sample_data {
            exr::prelude::FlatSamples::F32(v) => v.clone(),
            other => panic!("channel {name} is not f32: {other:?}"),
        }
    };
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        let want: Vec<f32> = f.color.iter().map(|p| p[c]).collect();
        assert_eq!(plane(name), want, "channel {name}");
    }
    assert_eq!(plane("A"), f.alpha);
    // Z is the depth where something was rendered and +inf ("no surface") where not.
    let z: Vec<f32> = (f.depth.iter().zip(&f.alpha))
        .map(|(&d, &a)| if a > 0.0 { d } else { f32::INFINITY })
        .collect();
    assert_eq!(plane("Z"), z);
    assert!(z.iter().any(|v| v.is_infinite()) && z.iter().any(|v| v.is_finite()));
}

#[test]
fn png_8_and_16_bit_read_back_within_quantisation() {
    let dir = tempfile::tempdir().unwrap();
    let f = test_frame();
    for (name, format, max) in [
        ("f8.png", ImageFormat::Png8, 255.0f32),
        ("f16.png", ImageFormat::Png16, 65535.0),
    ] {
        let path = dir.path().join(name);
        output::write_frame(&f, &path, format, false).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (f.width, f.height));
        let back = img.to_rgb32f();
        for (i, p) in back.pixels().enumerate() {
            for c in 0..3 {
                let want = f.color[i][c].clamp(0.0, 1.0);
                assert!(
                    (p.0[c] - want).abs() <= 0.5 / max + 1e-6,
                    "{name} pixel {i}: {} vs {want}",
                    p.0[c]
                );
            }
        }
        let is16 = matches!(img, image::DynamicImage::ImageRgb16(_));
        assert_eq!(is16, format == ImageFormat::Png16);
    }
}

#[test]
fn quantisation_matches_torchvision_save_image() {
    assert_eq!(output::to_u8(0.0), 0);
    assert_eq!(output::to_u8(1.0), 255);
    assert_eq!(output::to_u8(1.7), 255);
    assert_eq!(output::to_u8(-0.3), 0);
    assert_eq!(output::to_u8(0.5), 128); // 127.5 + 0.5 = 128
    assert_eq!(output::to_u8(0.499), 127);
    assert_eq!(output::to_u16(0.5), 32768);
}

#[test]
fn existing_files_are_not_overwritten_unless_asked() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("keep.png");
    std::fs::write(&path, b"precious").unwrap();
    let e = output::write_frame(&test_frame(), &path, ImageFormat::Png8, false).unwrap_err();
    assert!(matches!(e, OutputError::Exists(_)));
    assert!(e.to_string().contains("--overwrite"));
    assert_eq!(std::fs::read(&path).unwrap(), b"precious");
    output::write_frame(&test_frame(), &path, ImageFormat::Png8, true).unwrap();
    assert!(image::open(&path).is_ok());
}

#[test]
fn failed_writes_leave_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.png");
    let e = output::write_atomically(&path, false, |w| {
        use std::io::Write;
        w.write_all(b"half an image").unwrap();
        Err(OutputError::Encode {
            path: path.clone(),
            message: "simulated encoder failure".into(),
        })
    })
    .unwrap_err();
    assert!(e.to_string().contains("simulated"));
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "no partial or temporary file"
    );
    let missing_dir = dir.path().join("no/such/dir/out.png");
    let e = output::write_frame(&test_frame(), &missing_dir, ImageFormat::Png8, false).unwrap_err();
    assert!(e.to_string().contains("no/such/dir/out.png"), "{e}");
}

#[test]
fn format_is_chosen_from_the_extension() {
    use std::path::Path;
    assert_eq!(
        ImageFormat::from_path(Path::new("a.PNG"), false).unwrap(),
        ImageFormat::Png8
    );
    assert_eq!(
        ImageFormat::from_path(Path::new("a.png"), true).unwrap(),
        ImageFormat::Png16
    );
    assert_eq!(
        ImageFormat::from_path(Path::new("a.exr"), false).unwrap(),
        ImageFormat::Exr
    );
    assert!(ImageFormat::from_path(Path::new("a.jpg"), false).is_err());
}
