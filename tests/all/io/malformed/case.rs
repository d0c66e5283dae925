//! Cases of the malformed-input table: what a case writes, which loader reads it and what
//! must happen, with shorthands for scene, camera-file and COLMAP-model cases.

/// What a case must do.
pub(super) enum Expect {
    /// Loading fails with one sentence containing this fragment.
    Error(&'static str),
    /// The data is usable: it loads with this many Gaussians and renders (checked by
    /// [`check_render`]: the background for 0 Gaussians, else a visible splat at the centre).
    Renders(usize),
}

/// Which loader a case goes through.
#[derive(Clone, Copy, PartialEq)]
pub(super) enum Kind {
    Scene,
    Cameras,
}

pub(super) struct Case {
    /// Directory name under `malformed/`, and the name used in failure messages.
    pub(super) name: &'static str,
    pub(super) kind: Kind,
    /// Files to write, relative to the case directory.
    pub(super) files: Vec<(&'static str, Vec<u8>)>,
    /// What to load, relative to the case directory.
    pub(super) arg: &'static str,
    pub(super) expect: Expect,
}

pub(super) fn scene_case(
    name: &'static str,
    file: &'static str,
    bytes: Vec<u8>,
    expect: Expect,
) -> Case {
    Case {
        name,
        kind: Kind::Scene,
        files: vec![(file, bytes)],
        arg: file,
        expect,
    }
}

pub(super) fn camera_case(
    name: &'static str,
    file: &'static str,
    text: &str,
    expect: Expect,
) -> Case {
    Case {
        name,
        kind: Kind::Cameras,
        files: vec![(file, text.as_bytes().to_vec())],
        arg: file,
        expect,
    }
}

/// A COLMAP text model that must fail with `fragment`, or (bin) a binary one.
pub(super) fn colmap_case(
    name: &'static str,
    cams: Vec<u8>,
    images: Vec<u8>,
    bin: bool,
    fragment: &'static str,
) -> Case {
    Case {
        expect: Expect::Error(fragment),
        ..colmap_model_case(name, cams, images, Expect::Renders(0))
    }
    .binary(bin)
}

/// A COLMAP text model and what it must do.
pub(super) fn colmap_model_case(
    name: &'static str,
    cams: Vec<u8>,
    images: Vec<u8>,
    expect: Expect,
) -> Case {
    Case {
        name,
        kind: Kind::Cameras,
        files: vec![("model/cameras.txt", cams), ("model/images.txt", images)],
        arg: "model",
        expect,
    }
}

impl Case {
    /// The same COLMAP model's files named as a binary model's, when `bin`.
    fn binary(mut self, bin: bool) -> Case {
        if bin {
            self.files[0].0 = "model/cameras.bin";
            self.files[1].0 = "model/images.bin";
        }
        self
    }
}
