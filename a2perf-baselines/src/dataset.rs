//! Offline data for behavioural cloning: an in-memory [`Dataset`] of (observation, action) pairs
//! and the [`DatasetLoader`] trait through which pipelines feed it.

use std::path::{Path, PathBuf};

use a2perf_core::{ActMode, Action, Env, EnvSpec, Observation, Policy, RunError, rollout};
use serde::{Deserialize, Serialize};

/// Version of the JSON dataset file ([`Dataset::save_json`], `a2perf collect`'s
/// `samples.json`). 2: observation tensors carry their element type (`int32` ids are integers).
/// Files without a `format` field were written by older builds, with every id as a float; they
/// are refused rather than read as the wrong type.
pub const DATASET_FORMAT: u32 = 2;

/// The first field of a dataset file, read before the samples.
#[derive(Deserialize)]
struct FormatProbe {
    #[serde(default)]
    format: Option<u32>,
}

/// A dataset file as read.
#[derive(Deserialize)]
struct DatasetFileIn {
    #[serde(default)]
    format: Option<u32>,
    #[serde(default)]
    env_id: Option<String>,
    samples: Vec<Sample>,
}

/// A dataset file as written.
#[derive(Serialize)]
struct DatasetFileOut<'a> {
    format: u32,
    env_id: &'a Option<String>,
    samples: &'a [Sample],
}

/// One demonstration step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// What the demonstrator saw.
    pub observation: Observation,
    /// What it did.
    pub action: Action,
}

impl From<a2perf_core::Transition> for Sample {
    /// The demonstration step of a recorded transition: what was seen and what was done.
    fn from(t: a2perf_core::Transition) -> Self {
        Self {
            observation: t.observation,
            action: t.action,
        }
    }
}

/// Demonstrations in memory.
///
/// ```
/// use a2perf_baselines::dataset::{Dataset, Sample};
/// use a2perf_core::{Action, Observation};
/// let mut d = Dataset::default();
/// d.samples.push(Sample { observation: Observation::flat(vec![0.0]), action: Action::Discrete(1) });
/// assert_eq!(d.len(), 1);
/// ```
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// Environment id the data was collected on, when known.
    pub env_id: Option<String>,
    /// The samples.
    pub samples: Vec<Sample>,
}

impl Dataset {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Records `episodes` episodes of `policy` (in `mode`) on `env`, seeds `seed, seed+1, …`.
    pub fn collect(
        env: &mut dyn Env,
        policy: &mut dyn Policy,
        episodes: usize,
        seed: u64,
        mode: ActMode,
    ) -> Result<Self, RunError> {
        let mut samples = Vec::new();
        for e in 0..episodes {
            let ep = rollout(env, policy, seed.wrapping_add(e as u64), mode, true)?;
            samples.extend(ep.transitions.into_iter().map(Sample::from));
        }
        Ok(Self {
            env_id: Some(env.spec().id.clone()),
            samples,
        })
    }

    /// Reads a dataset written by [`save_json`](Self::save_json) (or `a2perf collect`), refusing
    /// files of another [`DATASET_FORMAT`]. The file is parsed as it is read, so the text is
    /// never held in memory beside the samples.
    ///
    /// ```
    /// use a2perf_baselines::dataset::{Dataset, Sample};
    /// use a2perf_core::{Action, Observation};
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("samples.json");
    /// let mut d = Dataset::default();
    /// d.samples.push(Sample { observation: Observation::flat(vec![0.5]), action: Action::Discrete(1) });
    /// d.save_json(&path).unwrap();
    /// assert_eq!(Dataset::load_json(&path).unwrap(), d);
    /// ```
    pub fn load_json(path: &Path) -> Result<Self, DatasetError> {
        let open = || {
            std::fs::File::open(path)
                .map(std::io::BufReader::new)
                .map_err(|e| DatasetError::Io {
                    path: path.to_path_buf(),
                    source: e,
                })
        };
        let malformed = |e: serde_json::Error| DatasetError::Malformed {
            path: path.to_path_buf(),
            reason: format!("line {}, column {}: {e}", e.line(), e.column()),
        };
        // The format decides the message: a file of another format usually fails to parse as
        // this one, and then it is read a second time, for its `format` field alone.
        let (parsed, format) = match serde_json::from_reader::<_, DatasetFileIn>(open()?) {
            Ok(file) => {
                let format = file.format;
                (Ok(file), format)
            }
            Err(e) if e.is_io() => {
                return Err(DatasetError::Io {
                    path: path.to_path_buf(),
                    source: e.into(),
                });
            }
            Err(e) => match serde_json::from_reader::<_, FormatProbe>(open()?) {
                Ok(probe) => (Err(e), probe.format),
                Err(_) => return Err(malformed(e)),
            },
        };
        match format {
            Some(DATASET_FORMAT) => {
                let file = parsed.map_err(malformed)?;
                Ok(Self {
                    env_id: file.env_id,
                    samples: file.samples,
                })
            }
            None => Err(DatasetError::Malformed {
                path: path.to_path_buf(),
                reason: format!(
                    "dataset of the old layout (no `format` field: every observation value, \
                     token ids included, stored as float32); this build reads format \
                     {DATASET_FORMAT}, with integer tensors as integers: collect it again"
                ),
            }),
            Some(v) => Err(DatasetError::Malformed {
                path: path.to_path_buf(),
                reason: format!(
                    "dataset format {v} is not supported (this build reads {DATASET_FORMAT})"
                ),
            }),
        }
    }

    /// Reads a dataset file as [`load_json`](Self::load_json) does, but hands each sample to
    /// `each` as soon as it is parsed instead of collecting them: one sample is held at a time,
    /// whatever the size of the file. Returns the number of samples. An error of `each` stops
    /// the reading and is returned as it is; a file that does not read as a dataset of this
    /// format gets `load_json`'s error.
    ///
    /// ```
    /// use a2perf_baselines::dataset::{Dataset, Sample};
    /// use a2perf_core::{Action, Observation};
    /// let path = std::env::temp_dir().join(format!("a2perf-doc-stream-{}.json", std::process::id()));
    /// let mut d = Dataset::default();
    /// for a in 0..3 {
    ///     d.samples.push(Sample { observation: Observation::flat(vec![0.5]), action: Action::Discrete(a) });
    /// }
    /// d.save_json(&path).unwrap();
    /// let mut actions = Vec::new();
    /// let n = Dataset::for_each_json_sample(&path, &mut |s| {
    ///     actions.push(s.action);
    ///     Ok(())
    /// })
    /// .unwrap();
    /// assert_eq!((n, actions.len()), (3, 3));
    /// std::fs::remove_file(&path).unwrap();
    /// ```
    pub fn for_each_json_sample(
        path: &Path,
        each: &mut dyn FnMut(Sample) -> Result<(), DatasetError>,
    ) -> Result<usize, DatasetError> {
        let file = std::fs::File::open(path).map_err(|e| DatasetError::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        let mut sink = SampleSink {
            each,
            stopped: None,
            count: 0,
            format: None,
            saw_samples: false,
        };
        let mut de = serde_json::Deserializer::from_reader(std::io::BufReader::new(file));
        let parsed =
            serde::de::DeserializeSeed::deserialize(&mut sink, &mut de).and_then(|()| de.end());
        if let Some(e) = sink.stopped {
            return Err(e);
        }
        match parsed {
            Ok(()) if sink.saw_samples && sink.format == Some(DATASET_FORMAT) => Ok(sink.count),
            Err(e) if e.is_io() => Err(DatasetError::Io {
                path: path.to_path_buf(),
                source: e.into(),
            }),
            // Not a dataset of this format as written (or a field order this reader does not
            // stream): the whole-file reader gives the error, or the samples.
            _ => {
                let rest = Self::load_json(path)?;
                let n = rest.samples.len();
                for s in rest.samples.into_iter().skip(sink.count) {
                    (sink.each)(s)?;
                }
                Ok(n)
            }
        }
    }

    /// Writes the dataset as compact JSON (atomically, streamed to the file), in format
    /// [`DATASET_FORMAT`]. Compact because a dataset is mostly numbers: pretty-printed, each takes
    /// a line of its own, and 100 web-navigation episodes came to 786 MB instead of 170 MB.
    pub fn save_json(&self, path: &Path) -> Result<(), DatasetError> {
        let file = DatasetFileOut {
            format: DATASET_FORMAT,
            env_id: &self.env_id,
            samples: &self.samples,
        };
        a2perf_core::write_json_compact_atomic(path, &file).map_err(|e| match e {
            a2perf_core::results::ResultsError::Io { path, source } => {
                DatasetError::Io { path, source }
            }
            other => DatasetError::Malformed {
                path: path.to_path_buf(),
                reason: other.to_string(),
            },
        })
    }
}

/// What [`Dataset::for_each_json_sample`] keeps while it walks a file: the samples go to `each`
/// as they are parsed (after a `format` of this build; the writer puts it first).
struct SampleSink<'a> {
    each: &'a mut dyn FnMut(Sample) -> Result<(), DatasetError>,
    /// The error `each` stopped the walk with.
    stopped: Option<DatasetError>,
    /// Samples handed to `each`.
    count: usize,
    format: Option<u32>,
    saw_samples: bool,
}

impl<'de> serde::de::DeserializeSeed<'de> for &mut SampleSink<'_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> serde::de::Visitor<'de> for &mut SampleSink<'_> {
    type Value = ();
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a dataset object")
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        use serde::de::Error;
        while let Some(key) = map.next_key::<String>()? {
            match key.as_str() {
                "format" => self.format = map.next_value()?,
                "samples" if self.format == Some(DATASET_FORMAT) => {
                    self.saw_samples = true;
                    map.next_value_seed(SampleSeq(&mut *self))?;
                }
                // Samples of an unknown or missing format: the whole-file reader says which.
                "samples" => return Err(A::Error::custom("samples before a supported format")),
                _ => {
                    map.next_value::<serde::de::IgnoredAny>()?;
                }
            }
        }
        Ok(())
    }
}

/// The `samples` array of a dataset file, walked element by element.
struct SampleSeq<'s, 'a>(&'s mut SampleSink<'a>);

impl<'de> serde::de::DeserializeSeed<'de> for SampleSeq<'_, '_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> serde::de::Visitor<'de> for SampleSeq<'_, '_> {
    type Value = ();
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("an array of samples")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        use serde::de::Error;
        while let Some(sample) = seq.next_element::<Sample>()? {
            if let Err(e) = (self.0.each)(sample) {
                self.0.stopped = Some(e);
                return Err(A::Error::custom("stopped by the consumer"));
            }
            self.0.count += 1;
        }
        Ok(())
    }
}

/// Errors reading datasets.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not a dataset.
    #[error("{}: {reason}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The data does not fit the environment.
    #[error("dataset does not fit environment `{env}`: {reason}")]
    Mismatch {
        /// Environment id.
        env: String,
        /// What is wrong.
        reason: String,
    },
}

/// Supplies a dataset for an environment (pipelines implement it to feed offline data, e.g.
/// from a Minari-style collection).
pub trait DatasetLoader: Send + Sync {
    /// The dataset for `spec`.
    fn load(&self, spec: &EnvSpec) -> Result<Dataset, DatasetError>;

    /// Hands the samples of the dataset for `spec` to `each`, in order, and returns their number;
    /// an error of `each` stops the reading and is returned. The default loads the dataset
    /// ([`load`](Self::load)) first; a loader that can read sample by sample (as
    /// [`JsonDatasetFile`] does) overrides it, so that a consumer keeping the samples in its own
    /// form (behavioural cloning's compact store) never holds the whole dataset twice.
    fn for_each_sample(
        &self,
        spec: &EnvSpec,
        each: &mut dyn FnMut(Sample) -> Result<(), DatasetError>,
    ) -> Result<usize, DatasetError> {
        let data = self.load(spec)?;
        let n = data.samples.len();
        for s in data.samples {
            each(s)?;
        }
        Ok(n)
    }
}

impl DatasetLoader for Dataset {
    fn load(&self, _spec: &EnvSpec) -> Result<Dataset, DatasetError> {
        Ok(self.clone())
    }

    /// Clones one sample at a time, not the whole dataset.
    fn for_each_sample(
        &self,
        _spec: &EnvSpec,
        each: &mut dyn FnMut(Sample) -> Result<(), DatasetError>,
    ) -> Result<usize, DatasetError> {
        for s in &self.samples {
            each(s.clone())?;
        }
        Ok(self.samples.len())
    }
}

/// Loads a JSON dataset file (see [`Dataset::save_json`]).
#[derive(Clone, Debug)]
pub struct JsonDatasetFile(pub PathBuf);

impl DatasetLoader for JsonDatasetFile {
    fn load(&self, _spec: &EnvSpec) -> Result<Dataset, DatasetError> {
        Dataset::load_json(&self.0)
    }

    /// Parses the file as it goes ([`Dataset::for_each_json_sample`]).
    fn for_each_sample(
        &self,
        _spec: &EnvSpec,
        each: &mut dyn FnMut(Sample) -> Result<(), DatasetError>,
    ) -> Result<usize, DatasetError> {
        Dataset::for_each_json_sample(&self.0, each)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datasets_of_the_old_all_float_layout_are_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        // What builds before typed observations wrote: no `format`, tensor data a float array.
        let old = r#"{"env_id":"WebNavigation-Difficulty-01-v0","samples":[{"observation":
            {"tensors":[{"name":"dom_tokens","shape":[2],"data":[3.0,4.0]}],"action_mask":null},
            "action":{"Discrete":1}}]}"#;
        std::fs::write(&path, old).unwrap();
        let err = Dataset::load_json(&path).unwrap_err().to_string();
        assert!(err.contains(&path.display().to_string()), "{err}");
        assert!(err.contains("old layout"), "{err}");
        std::fs::write(&path, r#"{"format":7,"env_id":null,"samples":[]}"#).unwrap();
        let err = Dataset::load_json(&path).unwrap_err().to_string();
        assert!(err.contains("format 7 is not supported"), "{err}");
    }

    #[test]
    fn integer_tensors_round_trip_as_integers() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        let big = (1 << 24) + 1;
        let observation = Observation {
            tensors: vec![a2perf_core::Tensor::new("ids", &[2], vec![big, 7])],
            action_mask: None,
        };
        let d = Dataset {
            env_id: None,
            samples: vec![Sample {
                observation,
                action: Action::Discrete(0),
            }],
        };
        d.save_json(&path).unwrap();
        let back = Dataset::load_json(&path).unwrap();
        assert_eq!(back, d);
        assert_eq!(
            back.samples[0].observation.tensors[0].data.as_i32(),
            Some(&[big, 7][..])
        );
    }

    #[test]
    fn datasets_are_written_compact() {
        // A web-navigation observation is mostly zero token ids; pretty-printed, each took a
        // line of its own (~30 bytes), which made 100 episodes a 786 MB file.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        let n = 10_000;
        let ids: Vec<i32> = (0..n).map(|i| if i % 10 == 0 { 129 } else { 0 }).collect();
        let d = Dataset {
            env_id: Some("WebNavigation-Difficulty-01-v0".into()),
            samples: vec![Sample {
                observation: Observation {
                    tensors: vec![a2perf_core::Tensor::new("dom_tokens", &[n], ids)],
                    action_mask: Some(vec![true; 40]),
                },
                action: Action::Discrete(3),
            }],
        };
        d.save_json(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(
            bytes.len() < 3 * n,
            "{} bytes for {n} ids: not compact",
            bytes.len()
        );
        assert!(!bytes.contains(&b'\n'), "a compact file has no line breaks");
        assert_eq!(Dataset::load_json(&path).unwrap(), d);
    }

    #[test]
    fn a_truncated_or_missing_dataset_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        let d = Dataset {
            env_id: None,
            samples: vec![Sample {
                observation: Observation::flat(vec![0.5, 1.5]),
                action: Action::Discrete(1),
            }],
        };
        d.save_json(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 10]).unwrap();
        let err = Dataset::load_json(&path).unwrap_err();
        assert!(matches!(err, DatasetError::Malformed { .. }), "{err:?}");
        let msg = err.to_string();
        assert!(msg.contains(&path.display().to_string()), "{msg}");
        assert!(msg.contains("line 1, column"), "{msg}");
        let missing = dir.path().join("none.json");
        let err = Dataset::load_json(&missing).unwrap_err();
        assert!(matches!(err, DatasetError::Io { .. }), "{err:?}");
        assert!(err.to_string().contains("none.json"), "{err}");
    }

    fn five_samples() -> Dataset {
        Dataset {
            env_id: Some("Toy-v0".into()),
            samples: (0..5)
                .map(|a| Sample {
                    observation: Observation {
                        tensors: vec![
                            a2perf_core::Tensor::new("x", &[2], vec![a as f32 * 0.25, -0.0]),
                            a2perf_core::Tensor::new("ids", &[1], vec![(1 << 24) + a as i32]),
                        ],
                        action_mask: Some(vec![true, a % 2 == 0]),
                    },
                    action: Action::Discrete(a),
                })
                .collect(),
        }
    }

    /// The streamed samples are the loaded ones, in order, and each is handed over as it is
    /// parsed.
    #[test]
    fn samples_stream_in_order_and_equal_the_loaded_ones() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        let d = five_samples();
        d.save_json(&path).unwrap();
        let mut seen = Vec::new();
        let n = Dataset::for_each_json_sample(&path, &mut |s| {
            seen.push(s);
            Ok(())
        })
        .unwrap();
        assert_eq!(n, 5);
        assert_eq!(seen, Dataset::load_json(&path).unwrap().samples);
        assert_eq!(seen, d.samples);
        // The loader trait's streaming gives the same, from the file and from memory.
        let spec = EnvSpec {
            id: "Toy-v0".into(),
            observation_space: a2perf_core::Space::uniform_box(&[1], 0.0, 1.0),
            action_space: a2perf_core::Space::Discrete { n: 2 },
            max_episode_steps: None,
            metadata: Default::default(),
        };
        for loader in [
            &JsonDatasetFile(path.clone()) as &dyn DatasetLoader,
            &d as &dyn DatasetLoader,
        ] {
            let mut again = Vec::new();
            let n = loader
                .for_each_sample(&spec, &mut |s| {
                    again.push(s);
                    Ok(())
                })
                .unwrap();
            assert_eq!((n, &again), (5, &d.samples));
        }
    }

    /// An error of the consumer stops the reading at that sample and comes back unchanged.
    #[test]
    fn a_consumer_error_stops_the_stream() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        five_samples().save_json(&path).unwrap();
        let mut calls = 0;
        let err = Dataset::for_each_json_sample(&path, &mut |_| {
            calls += 1;
            if calls == 2 {
                return Err(DatasetError::Mismatch {
                    env: "Toy-v0".into(),
                    reason: "sample 1: no".into(),
                });
            }
            Ok(())
        })
        .unwrap_err();
        assert_eq!(calls, 2);
        assert!(
            matches!(&err, DatasetError::Mismatch { reason, .. } if reason == "sample 1: no"),
            "{err:?}"
        );
    }

    /// Files that are not datasets of this format get the whole-file reader's error: old
    /// layout, unknown format, truncated, missing.
    #[test]
    fn the_stream_refuses_what_load_json_refuses_with_its_message() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("samples.json");
        let mut cases: Vec<Vec<u8>> = vec![
            br#"{"env_id":null,"samples":[{"observation":{"tensors":[{"name":"x","shape":[1],"data":[3.0]}],"action_mask":null},"action":{"Discrete":1}}]}"#.to_vec(),
            br#"{"format":7,"env_id":null,"samples":[]}"#.to_vec(),
            br#"{"format":2,"env_id":null}"#.to_vec(),
        ];
        five_samples().save_json(&path).unwrap();
        let whole = std::fs::read(&path).unwrap();
        cases.push(whole[..whole.len() - 40].to_vec());
        for bytes in cases {
            std::fs::write(&path, &bytes).unwrap();
            let want = Dataset::load_json(&path).unwrap_err().to_string();
            let got = Dataset::for_each_json_sample(&path, &mut |_| Ok(()))
                .unwrap_err()
                .to_string();
            assert_eq!(got, want);
            assert!(got.contains(&path.display().to_string()), "{got}");
        }
        let missing = dir.path().join("none.json");
        let err = Dataset::for_each_json_sample(&missing, &mut |_| Ok(())).unwrap_err();
        assert!(matches!(err, DatasetError::Io { .. }), "{err:?}");
    }

    #[test]
    fn a_dataset_that_cannot_be_written_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing-dir").join("samples.json");
        let err = Dataset::default().save_json(&path).unwrap_err();
        assert!(matches!(err, DatasetError::Io { .. }), "{err:?}");
        assert!(err.to_string().contains("missing-dir"), "{err}");
    }
}
