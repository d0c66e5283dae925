//! The training photos kept on the device (issue 61, item 2): each uploaded once, the loss
//! reads the same bits as when every photo is uploaded each time it is trained on
//! (`VERISPLAT_TRAIN_PHOTOS=host`), so the models are the same bytes, through
//! densification, an opacity reset and several rounds over the photos.

use crate::common::cli::verisplat_env;
use crate::common::dataset::make_dataset;

#[test]
fn photos_kept_on_the_device_train_the_same_model_as_photos_uploaded_each_time() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    make_dataset(&data, 12, 48, 36);
    let run = |out: &str, photos: &str| {
        let model = dir.path().join(out);
        let args = [
            "train",
            data.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--iterations",
            "200",
            "--densify-from-iter",
            "50",
            "--densification-interval",
            "50",
            "--opacity-reset-interval",
            "150",
            "--sh-degree",
            "1",
            "-q",
        ];
        let o = verisplat_env(&args, &[("VERISPLAT_TRAIN_PHOTOS", photos)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(model.join("point_cloud/iteration_200/point_cloud.ply")).unwrap()
    };
    let kept = run("kept", "device");
    let uploaded = run("uploaded", "host");
    assert!(kept.len() > 1000);
    assert!(kept == uploaded, "the models differ");
    // A value the variable does not know is refused.
    let refused = dir.path().join("refused");
    let o = verisplat_env(
        &[
            "train",
            data.to_str().unwrap(),
            "-o",
            refused.to_str().unwrap(),
            "-q",
        ],
        &[("VERISPLAT_TRAIN_PHOTOS", "gpu")],
    );
    assert!(!o.status.success());
    assert!(!refused.exists(), "a refused run wrote its model directory");
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("expected device or host"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
