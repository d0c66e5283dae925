//! [`CpuSource`]: the viewer's frames from the CPU reference renderer (`verisplat view
//! --cpu`), for machines without a Vulkan device and as the exact reference the GPU
//! frames are checked against.

use super::source::{
    encode_shot, frame_rgba8, render_options, ShotFormat, ViewFrame, ViewSettings, ViewSource,
};
use crate::core::camera::Camera;
use crate::core::frame::Frame;
use crate::core::scene::{ActivatedScene, Scene};
use crate::cpu;
use crate::render::{FrameStats, StageTimings};

/// Renders with [`crate::cpu`]; the settings become the same [`cpu::RenderOptions`] the
/// GPU source uses (and `render --cpu` builds from the matching flags), so the scene is
/// activated once and every slider applies per frame.
pub struct CpuSource {
    scene: ActivatedScene,
    sh_degree: u32,
    antialiased: bool,
    kernel: cpu::SplatKernel,
    rules: cpu::Rules,
}

impl CpuSource {
    /// A renderer of `scene` (with its [`Scene::kernel`]); `antialiased` turns on the
    /// opacity compensation of antialiased (mip) training, as `render --antialiased`.
    pub fn new(scene: &Scene, antialiased: bool) -> CpuSource {
        CpuSource {
            scene: scene.activated(),
            sh_degree: scene.sh_degree,
            antialiased,
            kernel: scene.kernel,
            rules: scene.rules,
        }
    }

    /// What renders the frames, for the page.
    pub fn device_name(&self) -> String {
        format!(
            "CPU reference renderer ({} threads)",
            rayon::current_num_threads()
        )
    }

    /// The reference pipeline stage by stage (as [`cpu::render_timed`]), keeping the
    /// count of visible Gaussians the page shows.
    fn render_frame(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
    ) -> anyhow::Result<(Frame, StageTimings, FrameStats)> {
        settings
            .validate(self.sh_degree)
            .map_err(anyhow::Error::msg)?;
        cam.validate()?;
        let opts = render_options(settings, self.antialiased, self.kernel, self.rules);
        let start = std::time::Instant::now();
        let mut lap = start;
        let mut take = || {
            let ms = lap.elapsed().as_secs_f64() * 1e3;
            lap = std::time::Instant::now();
            ms
        };
        let mut t = StageTimings::default();
        let projected = cpu::preprocess(&self.scene, cam, &opts);
        t.preprocess = take();
        let (keys, values) = cpu::tile_keys(&projected, cam);
        t.keys = take();
        let (sorted_keys, sorted_values) = cpu::sort_pairs(&keys, &values);
        t.sort = take();
        let (tx, ty) = cam.tile_grid();
        let ranges = cpu::tile_ranges(&sorted_keys, (tx * ty) as usize);
        t.ranges = take();
        let frame = cpu::blend(
            &projected,
            &sorted_values,
            &ranges,
            cam,
            opts.background,
            opts.kernel,
            opts.rules,
        );
        t.blend = take();
        t.total = start.elapsed().as_secs_f64() * 1e3;
        let stats = FrameStats {
            visible: projected.iter().filter(|p| p.tiles_touched() > 0).count() as u32,
            pairs: sorted_keys.len() as u64,
            ..Default::default()
        };
        Ok((frame, t, stats))
    }
}

impl ViewSource for CpuSource {
    fn render(&mut self, cam: &Camera, settings: &ViewSettings) -> anyhow::Result<ViewFrame> {
        let start = std::time::Instant::now();
        let (frame, timings, stats) = self.render_frame(cam, settings)?;
        Ok(ViewFrame {
            width: frame.width,
            height: frame.height,
            rgba8: frame_rgba8(&frame, settings.mode),
            timings,
            stats,
            wall_ms: start.elapsed().as_secs_f64() * 1e3,
            gaussians: self.scene.len() as u32,
        })
    }

    fn screenshot(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        format: ShotFormat,
    ) -> anyhow::Result<Vec<u8>> {
        let (frame, _, _) = self.render_frame(cam, settings)?;
        encode_shot(&frame, cam, settings, format)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The source's frame is `cpu::render` with the matching options, quantised.
    #[test]
    fn frames_equal_the_reference_render() {
        let scene = crate::io::demo::demo_scene();
        let cam = crate::core::camera::default_camera(&scene.positions, 64, 48);
        let mut src = CpuSource::new(&scene, false);
        let act = scene.activated();
        for settings in [
            ViewSettings::default(),
            ViewSettings {
                max_scale: Some(0.01),
                scale_modifier: 0.5,
                ..Default::default()
            },
        ] {
            let got = src.render(&cam, &settings).unwrap();
            let want = cpu::render(
                &act,
                &cam,
                &render_options(&settings, false, Default::default(), Default::default()),
            );
            assert_eq!(got.rgba8, frame_rgba8(&want, settings.mode));
            assert!(got.stats.visible > 0 && got.stats.pairs > 0);
        }
        // Bad settings are an error, not a frame.
        let bad = ViewSettings {
            scale_modifier: f32::NAN,
            ..Default::default()
        };
        assert!(src.render(&cam, &bad).is_err());
    }
}
