//! [`CpuSource`]: the viewer's frames from the CPU reference renderer (`vksplat view
//! --cpu`), for machines without a Vulkan device and as the exact reference the GPU
//! frames are checked against.

use super::pixels::{encode_screenshot, frame_rgba8};
use super::source::{FrameSource, ShotFormat, ViewFrame, ViewSettings};
use crate::camera::Camera;
use crate::cpu;
use crate::frame::Frame;
use crate::render::{FrameStats, StageTimings};
use crate::scene::filter::SceneFilter;
use crate::scene::{ActivatedScene, Scene};

/// The filters of the last frame and the scene they gave, so moving the camera does not
/// filter the scene again.
struct Filtered {
    filter: SceneFilter,
    scale_modifier: f32,
    scene: ActivatedScene,
}

/// Renders with [`crate::cpu`]; settings apply as `render --cpu` applies the matching
/// flags: `--max-scale`, `--min-opacity` and `--sh-degree` filter the scene before it is
/// activated, and the scale modifier multiplies the activated scales.
pub struct CpuSource {
    scene: Scene,
    antialiased: bool,
    cached: Option<Filtered>,
}

impl CpuSource {
    /// A renderer of `scene`; `antialiased` turns on the opacity compensation of
    /// antialiased (mip) training, as `render --antialiased`.
    pub fn new(scene: Scene, antialiased: bool) -> CpuSource {
        CpuSource {
            scene,
            antialiased,
            cached: None,
        }
    }

    /// What renders the frames, for the page.
    pub fn device_name(&self) -> String {
        format!(
            "CPU reference renderer ({} threads)",
            rayon::current_num_threads()
        )
    }

    /// The scene `settings` select, filtered and activated (cached between frames).
    fn scene_for(&mut self, settings: &ViewSettings) -> &ActivatedScene {
        let filter = SceneFilter {
            max_scale: settings.max_scale,
            // 0 keeps every Gaussian, as `render` without `--min-opacity`.
            min_opacity: (settings.min_opacity > 0.0).then_some(settings.min_opacity),
            crop: None,
            sh_degree: settings.sh_degree,
        };
        let fresh = self.cached.as_ref().map_or(true, |c| {
            c.filter != filter || c.scale_modifier != settings.scale_modifier
        });
        if fresh {
            let mut scene = if filter.is_identity_for(&self.scene) {
                self.scene.activated()
            } else {
                filter.apply(&self.scene).activated()
            };
            if settings.scale_modifier != 1.0 {
                for s in &mut scene.scales {
                    *s = s.map(|v| v * settings.scale_modifier);
                }
            }
            self.cached = Some(Filtered {
                filter,
                scale_modifier: settings.scale_modifier,
                scene,
            });
        }
        match &self.cached {
            Some(c) => &c.scene,
            None => unreachable!("the cache was filled above"),
        }
    }

    /// The reference pipeline stage by stage (as [`cpu::render_timed`]), keeping the
    /// count of visible Gaussians the page shows.
    fn render_frame(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
    ) -> anyhow::Result<(Frame, StageTimings, FrameStats)> {
        settings
            .validate(self.scene.sh_degree)
            .map_err(anyhow::Error::msg)?;
        cam.validate()?;
        let antialiased = self.antialiased;
        let scene = self.scene_for(settings);
        let start = std::time::Instant::now();
        let mut lap = start;
        let mut take = || {
            let ms = lap.elapsed().as_secs_f64() * 1e3;
            lap = std::time::Instant::now();
            ms
        };
        let mut t = StageTimings::default();
        let projected = cpu::preprocess(scene, cam, scene.sh_degree, antialiased);
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
            settings.background,
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

impl FrameSource for CpuSource {
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
        })
    }

    fn screenshot(
        &mut self,
        cam: &Camera,
        settings: &ViewSettings,
        format: ShotFormat,
    ) -> anyhow::Result<Vec<u8>> {
        let (frame, _, _) = self.render_frame(cam, settings)?;
        encode_screenshot(&frame, cam, settings, format)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The source's colour frame is `cpu::render` of the same camera, quantised.
    #[test]
    fn frame_equals_the_reference_render() {
        let scene = crate::demo_scene();
        let cam = crate::camera::default_camera(&scene.positions, 64, 48);
        let mut src = CpuSource::new(scene.clone(), false);
        let settings = ViewSettings::default();
        let got = src.render(&cam, &settings).unwrap();
        let want = cpu::render(&scene.activated(), &cam, &cpu::RenderOptions::default());
        assert_eq!(got.rgba8, frame_rgba8(&want, settings.mode));
        assert!(got.stats.visible > 0 && got.stats.pairs > 0);
        // A max-scale filter equals rendering the filtered scene.
        let filtered = ViewSettings {
            max_scale: Some(0.01),
            ..Default::default()
        };
        let got = src.render(&cam, &filtered).unwrap();
        let f = SceneFilter {
            max_scale: Some(0.01),
            ..Default::default()
        };
        let want = cpu::render(
            &f.apply(&scene).activated(),
            &cam,
            &cpu::RenderOptions::default(),
        );
        assert_eq!(got.rgba8, frame_rgba8(&want, filtered.mode));
        // Bad settings are an error, not a frame.
        let bad = ViewSettings {
            scale_modifier: f32::NAN,
            ..Default::default()
        };
        assert!(src.render(&cam, &bad).is_err());
    }
}
