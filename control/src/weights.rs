//! Weight files: safetensors with tensors `layers.{i}.weight` [out, in] and
//! `layers.{i}.bias` [out], and the metadata of DESIGN §4 in the header. A
//! PyTorch user loads them with `safetensors.torch.load_file`.
//!
//! The one loader of weight files: [`load`] reads, decodes and checks the role;
//! [`load_for`] also checks the machine parameters and Δt the network was
//! trained for against the caller's (daemon, simulator, training, benches and
//! tests all go through these). Reading is the only I/O of this crate; every
//! error names the file.
//!
//! The published weights live in one directory per machine under
//! `critic-weights/` ([`DEFAULT_DIR`] is the default machine's), each holding
//! [`CRITIC_FILE`] and [`ACTOR_FILE`].

use std::collections::HashMap;
use std::fmt;
use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;

use crate::cost::{CostForm, CostWeights};
use crate::encoder::{Encoder, ACTOR_INPUTS, CRITIC_INPUTS, DEFAULT_POS_SCALE, ENCODER_ID};
use crate::mlp::{Layer, Mlp, MlpError};
use crate::model::MachineParams;

/// Version of the file layout and metadata keys.
pub const FORMAT_VERSION: u32 = 1;
/// The only activation the kernels implement.
pub const ACTIVATION: &str = "softplus";
/// Actor outputs: mean (2) and log-std (2) of the Gaussian before tanh.
pub const ACTOR_OUTPUTS: usize = 4;
/// The critic's file name in a weights directory.
pub const CRITIC_FILE: &str = "critic.safetensors";
/// The actor's file name in a weights directory.
pub const ACTOR_FILE: &str = "actor.safetensors";
/// The default machine's (Avant 635) weights directory, relative to the
/// repository root (or an installation's `share/wlnav`).
pub const DEFAULT_DIR: &str = "critic-weights/avant635";

/// What a network file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NetworkRole {
    Critic,
    Actor,
}

impl NetworkRole {
    pub fn as_str(self) -> &'static str {
        match self {
            NetworkRole::Critic => "critic",
            NetworkRole::Actor => "actor",
        }
    }

    pub fn input_size(self) -> usize {
        match self {
            NetworkRole::Critic => CRITIC_INPUTS,
            NetworkRole::Actor => ACTOR_INPUTS,
        }
    }
}

impl fmt::Display for NetworkRole {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Header metadata of a weight file (DESIGN §4).
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkMetadata {
    pub role: NetworkRole,
    pub encoder_id: String,
    pub pos_scale: f64,
    pub activation: String,
    pub output_size: usize,
    /// Machine parameters and bounds the network was trained for.
    pub machine: MachineParams,
    /// Time step of the training environment [s].
    pub dt: f64,
    pub cost: CostWeights,
    pub gamma: f64,
    pub steps: u64,
    /// Lyapunov multiplier at the end of training.
    pub lambda_l: f64,
    pub git_commit: String,
}

impl NetworkMetadata {
    /// Metadata for a network of `role` with the defaults of this crate.
    pub fn new(role: NetworkRole, output_size: usize) -> Self {
        Self {
            role,
            encoder_id: ENCODER_ID.to_string(),
            pos_scale: DEFAULT_POS_SCALE,
            activation: ACTIVATION.to_string(),
            output_size,
            machine: MachineParams::default(),
            dt: 0.2,
            cost: CostWeights::default(),
            gamma: 0.99,
            steps: 0,
            lambda_l: 1.0,
            git_commit: "unknown".to_string(),
        }
    }

    /// The encoder this network was trained with.
    pub fn encoder(&self) -> Encoder {
        Encoder::new(self.machine, self.pos_scale)
    }

    fn to_map(&self) -> HashMap<String, String> {
        let mut m = HashMap::new();
        let mut put = |k: &str, v: String| {
            m.insert(k.to_string(), v);
        };
        put("format_version", FORMAT_VERSION.to_string());
        put("role", self.role.as_str().into());
        put("encoder", self.encoder_id.clone());
        put("encoder.pos_scale", self.pos_scale.to_string());
        put("activation", self.activation.clone());
        put("output_size", self.output_size.to_string());
        for (name, value) in self.machine.fields() {
            put(&format!("machine.{name}"), value.to_string());
        }
        put("dt", self.dt.to_string());
        put("cost.w", self.cost.w.map(|w| w.to_string()).join(","));
        put("cost.p", self.cost.p.to_string());
        put("cost.form", self.cost.form.as_str().into());
        put("gamma", self.gamma.to_string());
        put("steps", self.steps.to_string());
        put("lambda_l", self.lambda_l.to_string());
        put("git_commit", self.git_commit.clone());
        m
    }

    fn from_map(m: &HashMap<String, String>) -> Result<Self, WeightsProblem> {
        let get = |key: &'static str| m.get(key).ok_or(WeightsProblem::MissingKey(key));
        fn num<T: std::str::FromStr>(key: &'static str, s: &str) -> Result<T, WeightsProblem> {
            s.trim().parse().map_err(|_| WeightsProblem::BadValue {
                key: key.to_string(),
                value: s.to_string(),
            })
        }
        let version: u32 = num("format_version", get("format_version")?)?;
        if version != FORMAT_VERSION {
            return Err(WeightsProblem::Incompatible {
                key: "format_version".into(),
                file: version.to_string(),
                expected: FORMAT_VERSION.to_string(),
            });
        }
        let role = match get("role")?.as_str() {
            "critic" => NetworkRole::Critic,
            "actor" => NetworkRole::Actor,
            other => {
                return Err(WeightsProblem::BadValue {
                    key: "role".into(),
                    value: other.into(),
                })
            }
        };
        let encoder_id = get("encoder")?.clone();
        if encoder_id != ENCODER_ID {
            return Err(WeightsProblem::Incompatible {
                key: "encoder".into(),
                file: encoder_id,
                expected: ENCODER_ID.into(),
            });
        }
        let activation = get("activation")?.clone();
        if activation != ACTIVATION {
            return Err(WeightsProblem::Incompatible {
                key: "activation".into(),
                file: activation,
                expected: ACTIVATION.into(),
            });
        }
        let mut machine = MachineParams::default();
        {
            let field = |key: &'static str, dst: &mut f64| -> Result<(), WeightsProblem> {
                *dst = num(key, get(key)?)?;
                Ok(())
            };
            field("machine.l_f", &mut machine.l_f)?;
            field("machine.l_r", &mut machine.l_r)?;
            field("machine.beta_max", &mut machine.beta_max)?;
            field("machine.beta_dot_max", &mut machine.beta_dot_max)?;
            field("machine.v_max", &mut machine.v_max)?;
            field("machine.beta_ddot_max", &mut machine.beta_ddot_max)?;
            field("machine.a_max", &mut machine.a_max)?;
        }
        machine.validate().map_err(|e| WeightsProblem::BadValue {
            key: "machine".into(),
            value: e.to_string(),
        })?;
        let w_text = get("cost.w")?;
        let w: Vec<f64> = w_text
            .split(',')
            .map(|s| num::<f64>("cost.w", s))
            .collect::<Result<_, _>>()?;
        let w: [f64; 5] = w.try_into().map_err(|_| WeightsProblem::BadValue {
            key: "cost.w".into(),
            value: w_text.clone(),
        })?;
        let pos_scale: f64 = num("encoder.pos_scale", get("encoder.pos_scale")?)?;
        if !(pos_scale.is_finite() && pos_scale > 0.0) {
            return Err(WeightsProblem::BadValue {
                key: "encoder.pos_scale".into(),
                value: pos_scale.to_string(),
            });
        }
        Ok(Self {
            role,
            encoder_id,
            pos_scale,
            activation,
            output_size: num("output_size", get("output_size")?)?,
            machine,
            dt: num("dt", get("dt")?)?,
            cost: CostWeights {
                w,
                p: num("cost.p", get("cost.p")?)?,
                // Files written before the key existed used the quasi-norm.
                form: match m.get("cost.form") {
                    None => CostForm::QuasiNorm,
                    Some(s) => CostForm::parse(s).ok_or_else(|| WeightsProblem::BadValue {
                        key: "cost.form".into(),
                        value: s.clone(),
                    })?,
                },
            },
            gamma: num("gamma", get("gamma")?)?,
            steps: num("steps", get("steps")?)?,
            lambda_l: num("lambda_l", get("lambda_l")?)?,
            git_commit: get("git_commit")?.clone(),
        })
    }

    /// Checks the network was trained for the configured machine and time step:
    /// the encoder scales by the bounds, so other bounds mean other inputs. The
    /// problem names the first key that differs and both values.
    pub fn check_compatible(
        &self,
        configured: &MachineParams,
        dt: f64,
    ) -> Result<(), WeightsProblem> {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0);
        let mismatch = |key: String, trained: f64, configured: f64| WeightsProblem::Mismatch {
            key,
            trained: trained.to_string(),
            configured: configured.to_string(),
        };
        for ((name, file), (_, conf)) in self.machine.fields().into_iter().zip(configured.fields())
        {
            if !close(file, conf) {
                return Err(mismatch(format!("machine.{name}"), file, conf));
            }
        }
        if !close(self.dt, dt) {
            return Err(mismatch("dt".into(), self.dt, dt));
        }
        Ok(())
    }
}

/// What is wrong with a weight file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WeightsProblem {
    #[error("cannot read: {message}")]
    Read {
        kind: std::io::ErrorKind,
        message: String,
    },
    #[error("not a safetensors file: {0}")]
    Format(String),
    #[error("header has no metadata")]
    NoMetadata,
    #[error("metadata key `{0}` is missing")]
    MissingKey(&'static str),
    #[error("metadata key `{key}` has an invalid value `{value}`")]
    BadValue { key: String, value: String },
    #[error("metadata `{key}` = {file} is incompatible (expected {expected})")]
    Incompatible {
        key: String,
        file: String,
        expected: String,
    },
    /// Trained for another machine or Δt than the caller's.
    #[error("trained for `{key}` = {trained}, incompatible with the configured {configured}")]
    Mismatch {
        key: String,
        trained: String,
        configured: String,
    },
    #[error("tensor `{0}` is missing")]
    MissingTensor(String),
    #[error("unexpected tensor `{0}`")]
    UnexpectedTensor(String),
    #[error("tensor `{name}` has dtype {dtype}, expected F32 or F64")]
    Dtype { name: String, dtype: String },
    #[error("tensor `{name}` has shape {shape:?}, expected {expected}")]
    Shape {
        name: String,
        shape: Vec<usize>,
        expected: String,
    },
    #[error("tensor `{name}` has a non-finite value at index {index}")]
    NonFinite { name: String, index: usize },
    #[error("layer chain: {0}")]
    Chain(#[from] MlpError),
    #[error("network role is `{found}`, expected `{expected}`")]
    WrongRole {
        expected: NetworkRole,
        found: NetworkRole,
    },
}

/// A weight-file error, naming the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("weights file {source_name}: {problem}")]
pub struct WeightsError {
    pub source_name: String,
    pub problem: WeightsProblem,
}

impl WeightsError {
    pub fn new(source: &str, problem: WeightsProblem) -> Self {
        Self {
            source_name: source.to_string(),
            problem,
        }
    }
}

/// A validated network with its metadata.
#[derive(Debug, Clone)]
pub struct NetworkWeights {
    /// Where it came from (file name), for messages.
    pub source: String,
    pub meta: NetworkMetadata,
    pub mlp: Mlp,
}

impl NetworkWeights {
    /// These weights, if they are for a network of `role`.
    pub fn require_role(self, role: NetworkRole) -> Result<Self, WeightsError> {
        if self.meta.role != role {
            return Err(WeightsError::new(
                &self.source,
                WeightsProblem::WrongRole {
                    expected: role,
                    found: self.meta.role,
                },
            ));
        }
        Ok(self)
    }
}

/// Element type written to files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileDtype {
    F32,
    F64,
}

fn tensor_values(name: &str, view: &TensorView<'_>) -> Result<Vec<f64>, WeightsProblem> {
    let data = view.data();
    let values: Vec<f64> = match view.dtype() {
        Dtype::F32 => data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64)
            .collect(),
        Dtype::F64 => data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
            .collect(),
        other => {
            return Err(WeightsProblem::Dtype {
                name: name.into(),
                dtype: format!("{other:?}"),
            })
        }
    };
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(WeightsProblem::NonFinite {
            name: name.into(),
            index,
        });
    }
    Ok(values)
}

fn decode_inner(bytes: &[u8]) -> Result<(NetworkMetadata, Mlp), WeightsProblem> {
    let (_, header) =
        SafeTensors::read_metadata(bytes).map_err(|e| WeightsProblem::Format(e.to_string()))?;
    let meta_map = header
        .metadata()
        .as_ref()
        .ok_or(WeightsProblem::NoMetadata)?;
    let meta = NetworkMetadata::from_map(meta_map)?;
    let st = SafeTensors::deserialize(bytes).map_err(|e| WeightsProblem::Format(e.to_string()))?;

    let mut names: Vec<String> = st.names().into_iter().cloned().collect();
    names.sort();
    let mut layers = Vec::new();
    loop {
        let (wn, bn) = (
            format!("layers.{}.weight", layers.len()),
            format!("layers.{}.bias", layers.len()),
        );
        let w = match st.tensor(&wn) {
            Ok(w) => w,
            Err(_) if st.tensor(&bn).is_ok() => return Err(WeightsProblem::MissingTensor(wn)),
            Err(_) => break,
        };
        let b = st
            .tensor(&bn)
            .map_err(|_| WeightsProblem::MissingTensor(bn.clone()))?;
        let (n_out, n_in) = match w.shape() {
            [o, i] => (*o, *i),
            s => {
                return Err(WeightsProblem::Shape {
                    name: wn,
                    shape: s.to_vec(),
                    expected: "[out, in]".into(),
                })
            }
        };
        if b.shape() != [n_out] {
            return Err(WeightsProblem::Shape {
                name: bn,
                shape: b.shape().to_vec(),
                expected: format!("[{n_out}]"),
            });
        }
        let weight = tensor_values(&wn, &w)?;
        let bias = tensor_values(&bn, &b)?;
        names.retain(|n| n != &wn && n != &bn);
        layers.push(Layer {
            n_in,
            n_out,
            weight,
            bias,
        });
    }
    if let Some(extra) = names.into_iter().next() {
        return Err(WeightsProblem::UnexpectedTensor(extra));
    }
    if layers.is_empty() {
        return Err(WeightsProblem::MissingTensor("layers.0.weight".into()));
    }
    let mlp = Mlp::new(layers)?;
    let expected_in = meta.role.input_size();
    if mlp.input_size() != expected_in {
        return Err(WeightsProblem::Shape {
            name: "layers.0.weight".into(),
            shape: vec![mlp.layers()[0].n_out, mlp.input_size()],
            expected: format!("{expected_in} inputs for the {} encoder", meta.role),
        });
    }
    let last = mlp.layers().len() - 1;
    if mlp.output_size() != meta.output_size {
        return Err(WeightsProblem::Shape {
            name: format!("layers.{last}.weight"),
            shape: vec![mlp.output_size(), mlp.output_layer().n_in],
            expected: format!("{} outputs (metadata `output_size`)", meta.output_size),
        });
    }
    if meta.role == NetworkRole::Actor && meta.output_size != ACTOR_OUTPUTS {
        return Err(WeightsProblem::BadValue {
            key: "output_size".into(),
            value: meta.output_size.to_string(),
        });
    }
    Ok((meta, mlp))
}

/// Parses and validates a weight file's bytes; `source` names it in errors.
pub fn decode(bytes: &[u8], source: &str) -> Result<NetworkWeights, WeightsError> {
    let (meta, mlp) = decode_inner(bytes).map_err(|p| WeightsError::new(source, p))?;
    Ok(NetworkWeights {
        source: source.to_string(),
        meta,
        mlp,
    })
}

/// Reads and decodes the network file at `path` and checks it is a `role`
/// network. Errors name the file.
pub fn load(path: &Path, role: NetworkRole) -> Result<NetworkWeights, WeightsError> {
    let source = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| {
        WeightsError::new(
            &source,
            WeightsProblem::Read {
                kind: e.kind(),
                message: e.to_string(),
            },
        )
    })?;
    decode(&bytes, &source)?.require_role(role)
}

/// [`load`], and checks the network was trained for `machine` and time step
/// `dt` ([`NetworkMetadata::check_compatible`]): the message names the key and
/// both values.
pub fn load_for(
    path: &Path,
    role: NetworkRole,
    machine: &MachineParams,
    dt: f64,
) -> Result<NetworkWeights, WeightsError> {
    let w = load(path, role)?;
    w.meta
        .check_compatible(machine, dt)
        .map_err(|p| WeightsError::new(&w.source, p))?;
    Ok(w)
}

/// Serialises a network to safetensors bytes.
pub fn encode(
    meta: &NetworkMetadata,
    mlp: &Mlp,
    dtype: FileDtype,
) -> Result<Vec<u8>, WeightsError> {
    let mut buffers: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
    let bytes_of = |v: &[f64]| -> Vec<u8> {
        match dtype {
            FileDtype::F32 => v.iter().flat_map(|x| (*x as f32).to_le_bytes()).collect(),
            FileDtype::F64 => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    };
    for (i, l) in mlp.layers().iter().enumerate() {
        buffers.push((
            format!("layers.{i}.weight"),
            vec![l.n_out, l.n_in],
            bytes_of(&l.weight),
        ));
        buffers.push((format!("layers.{i}.bias"), vec![l.n_out], bytes_of(&l.bias)));
    }
    let st_dtype = match dtype {
        FileDtype::F32 => Dtype::F32,
        FileDtype::F64 => Dtype::F64,
    };
    let views: Vec<(String, TensorView<'_>)> = buffers
        .iter()
        .map(|(n, s, b)| {
            TensorView::new(st_dtype, s.clone(), b)
                .map(|v| (n.clone(), v))
                .map_err(|e| WeightsError::new(n, WeightsProblem::Format(e.to_string())))
        })
        .collect::<Result<_, _>>()?;
    safetensors::serialize(views, &Some(meta.to_map()))
        .map_err(|e| WeightsError::new("<encode>", WeightsProblem::Format(e.to_string())))
}

/// Deterministic random weights with PyTorch's default initialisation
/// (uniform ±1/√fan_in), so the MPC and daemon can run before training.
pub fn random_network(meta: NetworkMetadata, hidden: &[usize], seed: u64) -> NetworkWeights {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sizes = vec![meta.role.input_size()];
    sizes.extend_from_slice(hidden);
    sizes.push(meta.output_size);
    let layers = sizes
        .windows(2)
        .map(|w| {
            let (n_in, n_out) = (w[0], w[1]);
            let bound = 1.0 / (n_in as f64).sqrt();
            let mut draw = || rng.gen_range(-bound..bound);
            let weight = (0..n_in * n_out).map(|_| draw()).collect();
            let bias = (0..n_out).map(|_| draw()).collect();
            Layer {
                n_in,
                n_out,
                weight,
                bias,
            }
        })
        .collect();
    let mlp = Mlp::new(layers).expect("sizes chain by construction");
    NetworkWeights {
        source: format!("random(seed={seed})"),
        meta,
        mlp,
    }
}
