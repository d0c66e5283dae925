//! The model's whole state (parameters, Adam's moments and step counts, densification
//! statistics, the shader's weights) as a checkpoint's named arrays and scalars, and in
//! the layout of the records the device keeps ([`crate::train::device`]).

use super::adam::Moments;
use super::Model;
use crate::core::scene::Scene;

/// Where a Gaussian's colour starts in its device record ([`Model::record_floats`]): a
/// whole vec4 from the record's start.
pub(in crate::train) const COLOUR_OFFSET: usize =
    crate::core::shader_interface::COLOUR_OFFSET as usize;

/// A checkpoint's scalars (counts, degrees, step counts) by name.
pub(crate) type Scalars = serde_json::Map<String, serde_json::Value>;

impl Model {
    /// The whole state as named arrays and scalars (a checkpoint's content).
    pub(crate) fn state(&self) -> (Vec<(String, Vec<f32>)>, Scalars) {
        let s = &self.scene;
        let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let mut arrays = vec![
            ("positions".to_string(), flat(&s.positions)),
            ("log_scales".to_string(), flat(&s.log_scales)),
            (
                "rotations".to_string(),
                s.rotations.iter().flatten().copied().collect(),
            ),
            ("opacity_logits".to_string(), s.opacity_logits.clone()),
            ("sh".to_string(), s.sh.clone()),
            ("features".to_string(), s.features.clone()),
            ("grad_accum".to_string(), self.grad_accum.clone()),
            (
                "denom".to_string(),
                self.denom.iter().map(|&d| d as f32).collect(),
            ),
            ("max_radii".to_string(), self.max_radii.clone()),
            ("shader_m".to_string(), self.shader_moments.m.clone()),
            ("shader_v".to_string(), self.shader_moments.v.clone()),
        ];
        for (g, m) in self.moments.iter().enumerate() {
            arrays.push((format!("m{g}"), m.m.clone()));
            arrays.push((format!("v{g}"), m.v.clone()));
        }
        if let Some(f) = &self.mip_filters {
            arrays.push(("mip_filters".to_string(), f.clone()));
        }
        let mut meta = serde_json::Map::new();
        meta.insert("gaussians".into(), serde_json::json!(s.len()));
        meta.insert("sh_degree".into(), serde_json::json!(s.sh_degree));
        meta.insert("feature_count".into(), serde_json::json!(s.feature_count));
        meta.insert("kernel".into(), serde_json::json!(s.kernel.to_string()));
        meta.insert("rules".into(), serde_json::json!(s.rules.to_string()));
        meta.insert(
            "active_sh_degree".into(),
            serde_json::json!(self.active_sh_degree),
        );
        meta.insert("steps".into(), serde_json::json!(self.steps));
        (arrays, meta)
    }

    /// The model of [`Self::state`]'s arrays and scalars.
    pub(crate) fn from_state(
        mut arrays: std::collections::HashMap<String, Vec<f32>>,
        meta: &serde_json::Map<String, serde_json::Value>,
        shader: Option<crate::fields::mlp::Mlp>,
    ) -> Result<Self, String> {
        let num = |k: &str| {
            meta.get(k)
                .and_then(|v| v.as_u64())
                .ok_or(format!("has no {k}"))
        };
        let n = num("gaussians")? as usize;
        let sh_degree = num("sh_degree")? as u32;
        if sh_degree > 3 {
            return Err(format!("has SH degree {sh_degree}"));
        }
        let k = num("feature_count")? as usize;
        let has_mip_filters = arrays.contains_key("mip_filters");
        let mut take = |name: &str, len: usize| -> Result<Vec<f32>, String> {
            let v = arrays.remove(name).ok_or(format!("has no {name}"))?;
            if v.len() != len {
                return Err(format!("{name} holds {} values, not {len}", v.len()));
            }
            Ok(v)
        };
        let mut scene = Scene::empty(sh_degree);
        let stride = scene.sh_stride();
        let rows3 = |v: Vec<f32>| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        scene.positions = rows3(take("positions", n * 3)?);
        scene.log_scales = rows3(take("log_scales", n * 3)?);
        scene.rotations = take("rotations", n * 4)?
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        scene.opacity_logits = take("opacity_logits", n)?;
        scene.sh = take("sh", n * stride)?;
        scene.feature_count = k;
        scene.features = take("features", n * k)?;
        scene.kernel = meta
            .get("kernel")
            .and_then(|v| v.as_str())
            .and_then(|s| s.parse().ok())
            .ok_or("has no kernel")?;
        // Checkpoints from before the rules were recorded were trained with the original's.
        scene.rules = match meta.get("rules").and_then(|v| v.as_str()) {
            Some(r) => r.parse()?,
            None => Default::default(),
        };
        let mut model = Model::of(scene);
        model.grad_accum = take("grad_accum", n)?;
        model.denom = take("denom", n)?.iter().map(|&d| d as u32).collect();
        model.max_radii = take("max_radii", n)?;
        for (g, width) in [3, 3, 4, 1, stride, k].into_iter().enumerate() {
            model.moments[g] = Moments {
                m: take(&format!("m{g}"), n * width)?,
                v: take(&format!("v{g}"), n * width)?,
            };
        }
        let params = shader.as_ref().map_or(0, |m| {
            m.layers.iter().map(|l| (l.inputs + 1) * l.outputs).sum()
        });
        model.shader_moments = Moments {
            m: take("shader_m", params)?,
            v: take("shader_v", params)?,
        };
        model.shader = shader;
        // Mip-Splatting's 3D filter of a `--mip-filter` run, as it was stepping with.
        if has_mip_filters {
            model.mip_filters = Some(take("mip_filters", n)?);
        }
        model.active_sh_degree = num("active_sh_degree")? as u32;
        let steps = meta
            .get("steps")
            .and_then(|v| v.as_array())
            .filter(|a| a.len() == 7)
            .ok_or("has no step counts")?;
        for (t, v) in model.steps.iter_mut().zip(steps) {
            *t = v.as_u64().ok_or("has a bad step count")? as u32;
        }
        Ok(model)
    }

    /// Floats of one Gaussian's record on the device ([`crate::train::device`]): centre (3), log
    /// scales (3), quaternion (4), opacity logit, the 3D filter (`--mip-filter`; else
    /// unused), then from
    /// [`COLOUR_OFFSET`] its colour (SH coefficients up to the largest degree, or the
    /// feature channels of feature splats), padded to whole vec4s: the step loads and
    /// stores the colour a vec4 at a time (on a CPU device each buffer access is a loop
    /// over the lanes, a vec4 costs one).
    pub(in crate::train) fn record_floats(&self) -> usize {
        (COLOUR_OFFSET + self.colour_floats()).next_multiple_of(4)
    }

    /// Colour values per Gaussian that training learns: SH coefficients, or feature
    /// channels when a shader turns them into colour.
    pub(in crate::train) fn colour_floats(&self) -> usize {
        if self.shader.is_some() {
            self.scene.feature_count
        } else {
            self.scene.sh_stride()
        }
    }

    /// The colour's moments group: SH (4) or features (5).
    fn colour_group(&self) -> usize {
        if self.shader.is_some() {
            5
        } else {
            4
        }
    }

    /// Where each moments group sits in a device record: (group, floats per Gaussian,
    /// offset in the record).
    fn record_groups(&self) -> [(usize, usize, usize); 5] {
        [
            (0, 3, 0),
            (1, 3, 3),
            (2, 4, 6),
            (3, 1, 10),
            (self.colour_group(), self.colour_floats(), COLOUR_OFFSET),
        ]
    }

    /// The neural shader's weights and biases (flattened as `Mlp::gpu_words` orders
    /// them) and their Adam moments, for the device.
    pub(in crate::train) fn device_shader_state(&self) -> Option<[Vec<f32>; 3]> {
        let mlp = self.shader.as_ref()?;
        Some([
            mlp.flat_params(),
            self.shader_moments.m.clone(),
            self.shader_moments.v.clone(),
        ])
    }

    /// Takes [`Self::device_shader_state`]'s arrays back.
    pub(in crate::train) fn set_device_shader_state(&mut self, state: [Vec<f32>; 3]) {
        let [flat, m, v] = state;
        if let Some(mlp) = self.shader.as_mut() {
            mlp.set_flat_params(&flat);
            self.shader_moments = Moments { m, v };
        }
    }

    /// The parameters, Adam's moments (in the records' layout) and the densification
    /// statistics (sum of 2D-mean gradient norms, views seen, largest radius, 0) as the
    /// device holds them.
    pub(in crate::train) fn device_state(&self) -> [Vec<f32>; 4] {
        let s = &self.scene;
        let (n, r) = (self.len(), self.record_floats());
        let mut out = [
            vec![0f32; n * r],
            vec![0f32; n * r],
            vec![0f32; n * r],
            vec![0f32; n * 4],
        ];
        for (g, width, offset) in self.record_groups() {
            let params: Vec<f32> = match g {
                0 => s.positions.iter().flatten().copied().collect(),
                1 => s.log_scales.iter().flatten().copied().collect(),
                2 => s.rotations.iter().flatten().copied().collect(),
                3 => s.opacity_logits.clone(),
                4 => s.sh.clone(),
                _ => s.features.clone(),
            };
            for (a, src) in [&params, &self.moments[g].m, &self.moments[g].v]
                .into_iter()
                .enumerate()
            {
                for i in 0..n {
                    out[a][i * r + offset..i * r + offset + width]
                        .copy_from_slice(&src[i * width..(i + 1) * width]);
                }
            }
        }
        if let Some(filters) = &self.mip_filters {
            // The record's float 11: the 3D filter the step renders with (STEP_MIP).
            for (i, &f) in filters.iter().enumerate() {
                out[0][i * r + 11] = f;
            }
        }
        for i in 0..n {
            out[3][i * 4..i * 4 + 4].copy_from_slice(&[
                self.grad_accum[i],
                self.denom[i] as f32,
                self.max_radii[i],
                0.0,
            ]);
        }
        out
    }

    /// Takes the state of [`Self::device_state`]'s layout back (same Gaussians).
    pub(in crate::train) fn set_device_state(&mut self, state: [Vec<f32>; 4]) {
        let n = self.len();
        let r = self.record_floats();
        let c = self.colour_floats();
        let colour = self.colour_group();
        let [params, m, v, stats] = state;
        let rows = |src: &[f32], offset: usize, width: usize| -> Vec<f32> {
            (0..n)
                .flat_map(|i| src[i * r + offset..i * r + offset + width].iter().copied())
                .collect()
        };
        let s = &mut self.scene;
        let p3 = rows(&params, 0, 3);
        s.positions = p3.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let l3 = rows(&params, 3, 3);
        s.log_scales = l3.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let q4 = rows(&params, 6, 4);
        s.rotations = q4
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        s.opacity_logits = rows(&params, 10, 1);
        if colour == 4 {
            s.sh = rows(&params, COLOUR_OFFSET, c);
        } else {
            s.features = rows(&params, COLOUR_OFFSET, c);
        }
        for (g, width, offset) in self.record_groups() {
            self.moments[g] = Moments {
                m: rows(&m, offset, width),
                v: rows(&v, offset, width),
            };
        }
        self.grad_accum = (0..n).map(|i| stats[i * 4]).collect();
        self.denom = (0..n).map(|i| stats[i * 4 + 1] as u32).collect();
        self.max_radii = (0..n).map(|i| stats[i * 4 + 2]).collect();
    }
}
