//! The files of the surface passes (`--mode normal`, `--mode median-depth`;
//! [`crate::core::model::surface`]): OpenEXR with `N.x`, `N.y`, `N.z` and `A`, or `Z`
//! alone; PNG of the normals as colour or of the median depth through the depth colour
//! map.

use super::{depth_colormap, encode_png, write_exr_layer, OutputError};
use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::model::surface::{surface_planes, NormalSpace, SurfacePlanes, SURFACE_CHANNELS};
use std::io::Write;
use std::path::Path;

/// The surface planes of `frame` (rendered with the surface pass) with normals in
/// `space`; camera space needs the frame's camera.
pub fn frame_surface(
    frame: &Frame,
    camera: Option<&Camera>,
    space: NormalSpace,
    path: &Path,
) -> Result<SurfacePlanes, OutputError> {
    if frame.feature_count != SURFACE_CHANNELS
        || frame.features.len() != frame.alpha.len() * SURFACE_CHANNELS
    {
        return Err(OutputError::Encode {
            path: path.to_path_buf(),
            message: "the frame was not rendered with the surface pass (normals and median depth)"
                .into(),
        });
    }
    let rotation = match (space, camera) {
        (NormalSpace::World, _) => None,
        (NormalSpace::Camera, Some(cam)) => Some(cam),
        (NormalSpace::Camera, None) => {
            return Err(OutputError::Encode {
                path: path.to_path_buf(),
                message: "camera-space normals need the frame's camera".into(),
            })
        }
    };
    Ok(surface_planes(&frame.features, &frame.alpha, rotation))
}

/// The colour a normal PNG shows for unit normal `n` in `space`: `0.5 + 0.5 m`, with `m`
/// the normal in the usual normal-map axes: for camera space x right, y up, z towards
/// the camera (`m = (n.x, -n.y, -n.z)`; a surface facing the camera is (0.5, 0.5, 1.0),
/// light blue), for world space the world's axes (`m = n`). Black where there is no
/// normal (alpha 0): no unit normal maps to it.
pub fn normal_color(n: [f32; 3], space: NormalSpace) -> [f32; 3] {
    if n == [0.0; 3] {
        return [0.0; 3];
    }
    let m = match space {
        NormalSpace::Camera => [n[0], -n[1], -n[2]],
        NormalSpace::World => n,
    };
    m.map(|v| 0.5 + 0.5 * v)
}

/// Encodes the normals of `frame` as an RGB PNG ([`normal_color`]).
pub fn encode_png_normal(
    frame: &Frame,
    camera: Option<&Camera>,
    space: NormalSpace,
    sixteen_bit: bool,
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    let planes = frame_surface(frame, camera, space, path)?;
    let colours = Frame {
        color: planes
            .normals
            .iter()
            .map(|&n| normal_color(n, space))
            .collect(),
        alpha: Vec::new(),
        depth: Vec::new(),
        feature_count: 0,
        features: Vec::new(),
        ..*frame
    };
    encode_png(&colours, sixteen_bit, out, path)
}

/// Encodes the median depth of `frame` as an 8-bit PNG through the depth colour map
/// ([`depth_colormap`]: `range`, or the percentiles of the pixels that have one); black
/// where the transmittance never reaches 0.5.
pub fn encode_png_median_depth(
    frame: &Frame,
    range: Option<[f32; 2]>,
    out: &mut impl Write,
    path: &Path,
) -> Result<(), OutputError> {
    let planes = frame_surface(frame, None, NormalSpace::World, path)?;
    let covered: Vec<f32> = planes
        .median_depth
        .iter()
        .map(|&d| if d > 0.0 { 1.0 } else { 0.0 })
        .collect();
    let median = Frame {
        depth: planes.median_depth,
        alpha: covered,
        color: Vec::new(),
        feature_count: 0,
        features: Vec::new(),
        ..*frame
    };
    let colours = Frame {
        color: depth_colormap(&median, range),
        ..median
    };
    encode_png(&colours, false, out, path)
}

/// Encodes the normals of `frame` as OpenEXR channels `N.x`, `N.y`, `N.z` (unit length,
/// 0 where alpha is 0) and `A`, in half floats with `half`, and the camera in the header.
pub fn encode_exr_normal(
    frame: &Frame,
    camera: Option<&Camera>,
    space: NormalSpace,
    half: bool,
    out: &mut (impl Write + std::io::Seek),
    path: &Path,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let planes = frame_surface(frame, camera, space, path)?;
    let samples = |data: Vec<f32>| {
        if half {
            FlatSamples::F16(data.into_iter().map(f16::from_f32).collect())
        } else {
            FlatSamples::F32(data)
        }
    };
    let mut list: Vec<AnyChannel<FlatSamples>> = ["N.x", "N.y", "N.z"]
        .into_iter()
        .enumerate()
        .map(|(c, name)| {
            let plane = planes.normals.iter().map(|n| n[c]).collect();
            AnyChannel::new(name, samples(plane))
        })
        .collect();
    list.push(AnyChannel::new("A", samples(frame.alpha.clone())));
    write_exr_layer(list, frame, camera, out, path)
}

/// Encodes the median depth of `frame` as one 32-bit OpenEXR channel `Z` (`+inf`, "no
/// surface" as in the expected depth's `Z`, where the transmittance never reaches 0.5).
pub fn encode_exr_median_depth(
    frame: &Frame,
    camera: Option<&Camera>,
    out: &mut (impl Write + std::io::Seek),
    path: &Path,
) -> Result<(), OutputError> {
    use exr::prelude::*;
    let planes = frame_surface(frame, None, NormalSpace::World, path)?;
    let z = planes
        .median_depth
        .into_iter()
        .map(|d| if d > 0.0 { d } else { f32::INFINITY })
        .collect();
    write_exr_layer(
        vec![AnyChannel::new("Z", FlatSamples::F32(z))],
        frame,
        camera,
        out,
        path,
    )
}
