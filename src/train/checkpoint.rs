//! Training checkpoints: everything a run needs to continue exactly as if it had never
//! stopped (the Gaussians, Adam's moments and step counts, the densification statistics,
//! the SH degree in use, the shader and its moments, the random state and the rest of the
//! view order, the iteration, the photos' appearance transforms and their moments), as one safetensors file (`chkpntN.safetensors` in the model
//! directory): arrays as tensors, the rest in its metadata.

use super::model::Model;
use std::collections::HashMap;
use std::path::Path;

/// A run's state after `iteration`.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    /// The last iteration done.
    pub iteration: u32,
    /// The random state.
    pub rng: u64,
    /// The training views still to come in this round, last first.
    pub order: Vec<usize>,
    /// The model and its optimiser.
    pub model: Model,
    /// The data set and settings it belongs to (checked on resume).
    pub fingerprint: String,
    /// The training photos' appearance transforms and their optimiser
    /// (`--appearance affine`); their names are the data set's, not stored.
    pub appearance: Option<crate::train::appearance::Appearances>,
}

const META: &str = "verisplat_checkpoint";

impl Checkpoint {
    /// The file's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        use safetensors::tensor::TensorView;
        let (mut arrays, mut meta) = self.model.state();
        if let Some(a) = &self.appearance {
            let (more, steps) = a.state();
            arrays.extend(more);
            meta.insert("appearance_steps".into(), serde_json::json!(steps));
        }
        let le = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let mut owned: Vec<(String, safetensors::Dtype, Vec<usize>, Vec<u8>)> = arrays
            .into_iter()
            .map(|(name, values)| {
                let len = values.len();
                (name, safetensors::Dtype::F32, vec![len], le(&values))
            })
            .collect();
        if let Some(mlp) = &self.model.shader {
            let bytes = mlp.to_safetensors();
            owned.push((
                "shader_file".into(),
                safetensors::Dtype::U8,
                vec![bytes.len()],
                bytes,
            ));
        }
        let views = owned.iter().map(|(name, dtype, shape, data)| {
            (
                name.clone(),
                TensorView::new(*dtype, shape.clone(), data).expect("the shape holds the data"),
            )
        });
        let mut m = meta;
        m.insert("iteration".into(), serde_json::json!(self.iteration));
        m.insert("rng".into(), serde_json::json!(self.rng.to_string()));
        m.insert("order".into(), serde_json::json!(self.order));
        m.insert("fingerprint".into(), serde_json::json!(self.fingerprint));
        let info = HashMap::from([(META.to_string(), serde_json::Value::Object(m).to_string())]);
        safetensors::serialize(views, Some(info)).expect("tensors of matching shapes")
    }

    /// Reads a checkpoint file.
    pub fn load(path: &Path) -> Result<Checkpoint, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
        let tensors = safetensors::SafeTensors::deserialize(&bytes)
            .map_err(|e| format!("is not a checkpoint (safetensors): {e}"))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(&bytes)
            .map_err(|e| format!("is not a checkpoint: {e}"))?;
        let text = header
            .metadata()
            .as_ref()
            .and_then(|m| {
                m.iter()
                    .find(|(k, _)| crate::core::former_name::matches_key(k, META))
                    .map(|(_, v)| v.clone())
            })
            .ok_or("is not a verisplat training checkpoint (no description)")?;
        let meta: serde_json::Map<String, serde_json::Value> =
            serde_json::from_str(&text).map_err(|e| format!("has a broken description: {e}"))?;
        let mut arrays = HashMap::new();
        for (name, view) in tensors.tensors() {
            if name == "shader_file" {
                continue;
            }
            if view.dtype() != safetensors::Dtype::F32 {
                return Err(format!("tensor {name} is not F32"));
            }
            let v: Vec<f32> = view
                .data()
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            arrays.insert(name, v);
        }
        let shader = match tensors.tensor("shader_file") {
            Ok(view) => Some(
                crate::fields::mlp::Mlp::parse(view.data(), None)
                    .map_err(|e| format!("its shader: {e}"))?,
            ),
            Err(_) => None,
        };
        let steps = match meta.get("appearance_steps") {
            None => None,
            Some(v) => Some(
                v.as_array()
                    .ok_or("has a broken appearance_steps")?
                    .iter()
                    .map(|s| {
                        s.as_u64()
                            .map(|x| x as u32)
                            .ok_or("a bad appearance step count")
                    })
                    .collect::<Result<Vec<u32>, _>>()?,
            ),
        };
        let appearance =
            crate::train::appearance::Appearances::from_state(&mut arrays, steps, Vec::new())?;
        let model = Model::from_state(arrays, &meta, shader)?;
        let num = |k: &str| {
            meta.get(k)
                .and_then(|v| v.as_u64())
                .ok_or(format!("has no {k}"))
        };
        Ok(Checkpoint {
            iteration: num("iteration")? as u32,
            rng: meta
                .get("rng")
                .and_then(|v| v.as_str())
                .and_then(|s| s.parse().ok())
                .ok_or("has no random state")?,
            order: meta
                .get("order")
                .and_then(|v| v.as_array())
                .ok_or("has no view order")?
                .iter()
                .map(|v| v.as_u64().map(|x| x as usize).ok_or("a bad view index"))
                .collect::<Result<_, _>>()?,
            model,
            fingerprint: meta
                .get("fingerprint")
                .and_then(|v| v.as_str())
                .unwrap_or_default()
                .to_string(),
            appearance,
        })
    }
}
