//! Datasets in Minari's on-disk layout with its `arrow` storage, readable by
//! `minari.load_dataset` (Minari ≥ 0.5 with `pyarrow`) without any HDF5 library:
//!
//! ```text
//! <root>/<dataset_id>/data/metadata.json          dataset metadata (spaces as Minari JSON)
//! <root>/<dataset_id>/data/<episode>/metadata.json {"id", "total_steps", "seed"}
//! <root>/<dataset_id>/data/<episode>/part-0.arrow  one Arrow IPC record batch per episode
//! ```
//!
//! As Minari stores them, an episode of `n` steps has `n + 1` rows: every observation including
//! the last, with actions, rewards, terminations and truncations padded by one zero row.

use std::fmt::Write as _;
use std::io;
use std::path::Path;

use a2perf_core::{Action, DType, Observation, Space, TensorData};

use super::arrow::{self, Column};

/// Minari's dataset format version written in the metadata (supported by every Minari 0.5).
pub const MINARI_VERSION: &str = "0.5.0";

/// A bound as JSON text: `float32` bounds as the `f32` they are (`Infinity` for unbounded),
/// integer bounds as integers.
fn json_bound(x: f64, dtype: DType) -> String {
    if dtype.is_integer() {
        let (min, max) = dtype.range();
        format!("{}", x.clamp(min, max) as i64)
    } else if x.is_finite() {
        format!("{:?}", x as f32)
    } else if x > 0.0 {
        "Infinity".into()
    } else {
        "-Infinity".into()
    }
}

fn nested(values: &[f64], shape: &[usize], dtype: DType) -> String {
    match shape {
        [] => values
            .first()
            .map_or_else(|| "0".into(), |v| json_bound(*v, dtype)),
        [_] => format!(
            "[{}]",
            values
                .iter()
                .map(|v| json_bound(*v, dtype))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        [n, rest @ ..] => {
            let step: usize = rest.iter().product();
            let parts: Vec<String> = (0..*n)
                .map(|i| nested(&values[i * step..(i + 1) * step], rest, dtype))
                .collect();
            format!("[{}]", parts.join(", "))
        }
    }
}

/// A space serialised as Minari does (`minari.serialization.serialize_space`), as a JSON
/// object text (Python's `json` reads the `Infinity` bounds).
pub fn space_json(space: &Space) -> String {
    match space {
        Space::Discrete { n } => {
            format!(r#"{{"type": "Discrete", "dtype": "int64", "start": 0, "n": {n}}}"#)
        }
        Space::Box {
            low,
            high,
            shape,
            dtype,
        } => format!(
            r#"{{"type": "Box", "dtype": "{}", "shape": {:?}, "low": {}, "high": {}}}"#,
            dtype.name(),
            shape,
            nested(low, shape, *dtype),
            nested(high, shape, *dtype)
        ),
        Space::Dict(items) => {
            let mut s = String::from(r#"{"type": "Dict", "subspaces": {"#);
            for (i, (k, sub)) in items.iter().enumerate() {
                if i > 0 {
                    s.push_str(", ");
                }
                let _ = write!(
                    s,
                    "{}: {}",
                    serde_json::Value::String(k.clone()),
                    space_json(sub)
                );
            }
            s.push_str("}}");
            s
        }
    }
}

fn bad(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, msg)
}

fn tensor_column(
    name: &str,
    space: &Space,
    obs: &[&Observation],
    flat: bool,
) -> io::Result<Column> {
    match space {
        Space::Box { low, dtype, .. } => {
            let size = low.len();
            let mut values = TensorData::zeros(*dtype, 0);
            for o in obs {
                let t = if flat {
                    o.tensors.first()
                } else {
                    o.tensor(name)
                };
                let t = t.ok_or_else(|| bad(format!("observation `{name}` is missing")))?;
                if t.data.len() != size || t.dtype() != *dtype {
                    return Err(bad(format!(
                        "observation `{name}` has {} {} values, its space {size} {dtype}",
                        t.data.len(),
                        t.dtype()
                    )));
                }
                match (&mut values, &t.data) {
                    (TensorData::F32(v), TensorData::F32(x)) => v.extend_from_slice(x),
                    (TensorData::I32(v), TensorData::I32(x)) => v.extend_from_slice(x),
                    (TensorData::I64(v), TensorData::I64(x)) => v.extend_from_slice(x),
                    (TensorData::U8(v), TensorData::U8(x)) => v.extend_from_slice(x),
                    // Same element type, checked above.
                    _ => {}
                }
            }
            Ok(Column::Fixed { size, values })
        }
        Space::Discrete { .. } => obs
            .iter()
            .map(|o| {
                let t = if flat {
                    o.tensors.first()
                } else {
                    o.tensor(name)
                };
                t.and_then(|t| t.data.get_f64(0))
                    .map(|v| v as i64)
                    .ok_or_else(|| bad(format!("observation `{name}` is missing")))
            })
            .collect::<io::Result<Vec<_>>>()
            .map(Column::I64),
        Space::Dict(items) => items
            .iter()
            .map(|(k, s)| Ok((k.clone(), tensor_column(k, s, obs, false)?)))
            .collect::<io::Result<Vec<_>>>()
            .map(Column::Struct),
    }
}

fn action_column(space: &Space, actions: &[Action]) -> io::Result<Column> {
    match space {
        Space::Discrete { .. } => {
            let mut v: Vec<i64> = actions
                .iter()
                .map(|a| match a {
                    Action::Discrete(i) => Ok(*i as i64),
                    Action::Continuous(_) => {
                        Err(bad("continuous action in a discrete space".into()))
                    }
                })
                .collect::<io::Result<_>>()?;
            v.push(0);
            Ok(Column::I64(v))
        }
        Space::Box { low, .. } => {
            let size = low.len();
            let mut values = Vec::with_capacity(size * (actions.len() + 1));
            for a in actions {
                match a {
                    Action::Continuous(x) if x.len() == size => values.extend_from_slice(x),
                    _ => return Err(bad(format!("action does not fit a box of {size}"))),
                }
            }
            values.extend(std::iter::repeat_n(0.0, size));
            Ok(Column::Fixed {
                size,
                values: TensorData::F32(values),
            })
        }
        Space::Dict(_) => Err(bad("dict action spaces are not supported".into())),
    }
}

/// One recorded episode.
#[derive(Clone, Debug)]
pub struct EpisodeRecord {
    /// `n + 1` observations (the last is the final one).
    pub observations: Vec<Observation>,
    /// `n` actions.
    pub actions: Vec<Action>,
    /// `n` rewards.
    pub rewards: Vec<f64>,
    /// `n` termination flags.
    pub terminations: Vec<bool>,
    /// `n` truncation flags.
    pub truncations: Vec<bool>,
    /// Reset seed.
    pub seed: u64,
}

/// Writes episode `id` under `data_dir` (`<dataset>/data`).
pub fn write_episode(
    data_dir: &Path,
    id: usize,
    ep: &EpisodeRecord,
    observation_space: &Space,
    action_space: &Space,
) -> io::Result<()> {
    let n = ep.actions.len();
    if ep.observations.len() != n + 1 || ep.rewards.len() != n {
        return Err(bad(format!(
            "episode {id}: {} observations, {n} actions, {} rewards",
            ep.observations.len(),
            ep.rewards.len()
        )));
    }
    let obs: Vec<&Observation> = ep.observations.iter().collect();
    let pad = |mut v: Vec<bool>| {
        v.push(false);
        Column::Bool(v)
    };
    let mut rewards = ep.rewards.clone();
    rewards.push(0.0);
    let cols = vec![
        (
            "observations".to_string(),
            tensor_column("obs", observation_space, &obs, true)?,
        ),
        (
            "actions".to_string(),
            action_column(action_space, &ep.actions)?,
        ),
        ("rewards".to_string(), Column::F64(rewards)),
        ("terminations".to_string(), pad(ep.terminations.clone())),
        ("truncations".to_string(), pad(ep.truncations.clone())),
    ];
    let dir = data_dir.join(id.to_string());
    std::fs::create_dir_all(&dir)?;
    arrow::write_file(&dir.join("part-0.arrow"), &cols)?;
    let meta = serde_json::json!({"id": id, "total_steps": n, "seed": ep.seed});
    a2perf_core::write_atomic(&dir.join("metadata.json"), meta.to_string().as_bytes())
}

/// Writes the dataset's `metadata.json`; `extra` keys (provenance) are merged in.
#[allow(clippy::too_many_arguments)]
pub fn write_metadata(
    data_dir: &Path,
    dataset_id: &str,
    observation_space: &Space,
    action_space: &Space,
    total_episodes: usize,
    total_steps: usize,
    algorithm_name: &str,
    extra: serde_json::Map<String, serde_json::Value>,
) -> io::Result<()> {
    let mut meta = serde_json::json!({
        "dataset_id": dataset_id,
        "minari_version": MINARI_VERSION,
        "data_format": "arrow",
        "jpeg_encoding": false,
        "observation_space": space_json(observation_space),
        "action_space": space_json(action_space),
        "total_episodes": total_episodes,
        "total_steps": total_steps,
        "algorithm_name": algorithm_name,
        "author": ["a2perf collect"],
        "requirements": [],
    });
    if let Some(m) = meta.as_object_mut() {
        m.extend(extra);
    }
    std::fs::create_dir_all(data_dir)?;
    a2perf_core::write_atomic(&data_dir.join("metadata.json"), meta.to_string().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spaces_serialise_as_minari_does() {
        let b = Space::Box {
            low: vec![f64::NEG_INFINITY, 0.0, 0.0, 0.0],
            high: vec![1.0; 4],
            shape: vec![2, 2],
            dtype: DType::F32,
        };
        let s = space_json(&b);
        assert!(
            s.contains(r#""low": [[-Infinity, 0.0], [0.0, 0.0]]"#),
            "{s}"
        );
        let ids = Space::uniform_box_of(&[2], DType::I32, 0.0, 14_999.0);
        assert_eq!(
            space_json(&ids),
            r#"{"type": "Box", "dtype": "int32", "shape": [2], "low": [0, 0], "high": [14999, 14999]}"#
        );
        let d = Space::Dict(vec![("a".into(), Space::Discrete { n: 3 })]);
        assert_eq!(
            space_json(&d),
            r#"{"type": "Dict", "subspaces": {"a": {"type": "Discrete", "dtype": "int64", "start": 0, "n": 3}}}"#
        );
    }
}
