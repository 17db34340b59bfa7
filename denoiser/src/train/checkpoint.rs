//! Resumable checkpoints: weights, optimizer state and run state of a training run.
//!
//! These are not the shipped weight files: `pixguide train` writes a finished run's output with
//! [`crate::weights::save`] (f16 tensors, config and provenance in the metadata). Checkpoints
//! keep f32, since a resumed run must continue bit for bit.
//!
//! Weights: safetensors, one f32 tensor per parameter named by its module path
//! (`diffuse.d_g.net.layers.0.weight`), string metadata alongside. The optimizer state is
//! burn's own record (burnpack bytes); burn keys it by parameter id, and ids are fresh for every
//! model built, so a checkpoint also stores each path's id and loading restores those ids.
//! Every file is written to a temporary name and renamed, so a crash leaves the previous
//! checkpoint intact; `state.json` is written last and names the step the other files hold.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::optim::{ModuleOptimizer, OptimizerRecord};
use burn::tensor::{Tensor, TensorData};

use super::TrainError;
use crate::method::MethodModel;

fn io(path: &Path, e: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint(format!("{}: {e}", path.display()))
}

/// Temp file + rename in the same folder.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(|e| io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| io(path, e))
}

/// Every float parameter: path → (id, shape, values).
#[derive(Default)]
struct Collect {
    path: Vec<String>,
    out: Vec<(String, ParamId, Vec<usize>, Vec<f32>)>,
}

impl ModuleVisitor for Collect {
    fn enter_module(&mut self, name: &str, _container: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container: &str) {
        self.path.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let tensor = param.val();
        let shape = tensor.dims().to_vec();
        let data = tensor.into_data().convert::<f32>();
        self.out.push((self.path.join("."), param.id, shape, data.try_to_vec::<f32>().expect("f32 data")));
    }
}

/// The parameters of a model by path: (id, shape, values).
pub fn parameters<M: Module>(model: &M) -> Vec<(String, ParamId, Vec<usize>, Vec<f32>)> {
    let mut c = Collect::default();
    model.visit(&mut c);
    c.out
}

/// Path → parameter id, for restoring optimizer state.
pub fn param_ids<M: Module>(model: &M) -> BTreeMap<String, u64> {
    parameters(model).into_iter().map(|(p, id, _, _)| (p, id.val())).collect()
}

/// Serialises the parameters to safetensors bytes with `metadata`.
pub fn weights_bytes<M: Module>(model: &M, metadata: &BTreeMap<String, String>) -> Result<Vec<u8>, TrainError> {
    let params = parameters(model);
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> =
        params.into_iter().map(|(p, _, s, v)| (p, s, v.iter().flat_map(|x| x.to_le_bytes()).collect())).collect();
    let views: Vec<(String, safetensors::tensor::TensorView)> = bytes
        .iter()
        .map(|(p, s, b)| {
            Ok((
                p.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                    .map_err(|e| TrainError::Checkpoint(format!("{p}: {e}")))?,
            ))
        })
        .collect::<Result<_, TrainError>>()?;
    let meta: HashMap<String, String> = metadata.clone().into_iter().collect();
    safetensors::serialize(views, Some(meta)).map_err(|e| TrainError::Checkpoint(e.to_string()))
}

pub fn save_weights<M: Module>(path: &Path, model: &M, metadata: &BTreeMap<String, String>) -> Result<(), TrainError> {
    write_atomically(path, &weights_bytes(model, metadata)?)
}

/// Replaces every parameter by the file's tensor of the same path (and, if given, restores
/// its id). Every parameter must be present with the same shape.
struct Load<'a> {
    tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
    ids: Option<&'a BTreeMap<String, u64>>,
    path: Vec<String>,
    errors: Vec<String>,
}

impl ModuleMapper for Load<'_> {
    fn enter_module(&mut self, name: &str, _container: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container: &str) {
        self.path.pop();
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let path = self.path.join(".");
        let Some((shape, values)) = self.tensors.remove(&path) else {
            self.errors.push(format!("tensor `{path}` missing"));
            return param;
        };
        let dims = param.val().dims().to_vec();
        if dims != shape {
            self.errors.push(format!("tensor `{path}` has shape {shape:?}, the model expects {dims:?}"));
            return param;
        }
        let mut p = param.map(|t| {
            let grad = t.is_require_grad();
            let n = Tensor::<D>::from_data(TensorData::new(values, shape), &t.device());
            if grad {
                n.require_grad()
            } else {
                n
            }
        });
        if let Some(id) = self.ids.and_then(|m| m.get(&path)) {
            p.id = ParamId::from(*id);
        }
        p
    }
}

/// Tensors by name: shape and values.
pub type NamedTensors = HashMap<String, (Vec<usize>, Vec<f32>)>;

/// Reads a weights file: tensors by name and the metadata.
pub fn read_weights(path: &Path) -> Result<(NamedTensors, BTreeMap<String, String>), TrainError> {
    let bytes = std::fs::read(path).map_err(|e| io(path, e))?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).map_err(|e| io(path, e))?;
    let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| io(path, e))?;
    let mut out = HashMap::new();
    for (name, t) in st.tensors() {
        if t.dtype() != safetensors::Dtype::F32 {
            return Err(io(path, format!("tensor `{name}` is {:?}, expected f32", t.dtype())));
        }
        let v: Vec<f32> = t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        out.insert(name, (t.shape().to_vec(), v));
    }
    let meta = meta.metadata().clone().unwrap_or_default().into_iter().collect();
    Ok((out, meta))
}

/// Loads weights into `model` (which fixes the architecture); extra tensors in the file are an
/// error too, since they mean the file is for another method or size.
pub fn load_weights<M: Module>(
    path: &Path,
    model: M,
    ids: Option<&BTreeMap<String, u64>>,
) -> Result<(M, BTreeMap<String, String>), TrainError> {
    let (tensors, meta) = read_weights(path)?;
    let mut l = Load { tensors, ids, path: Vec::new(), errors: Vec::new() };
    let model = model.map(&mut l);
    if !l.tensors.is_empty() {
        let mut extra: Vec<&String> = l.tensors.keys().collect();
        extra.sort();
        l.errors.push(format!("unexpected tensors {extra:?} (another method or preset?)"));
    }
    if !l.errors.is_empty() {
        return Err(io(path, l.errors.join("; ")));
    }
    Ok((model, meta))
}

pub fn save_optimizer(path: &Path, optim: &ModuleOptimizer) -> Result<(), TrainError> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    optim.to_record().save(&tmp).map_err(|e| io(&tmp, format!("{e:?}")))?;
    std::fs::rename(&tmp, path).map_err(|e| io(path, e))
}

pub fn load_optimizer(path: &Path, optim: ModuleOptimizer) -> Result<ModuleOptimizer, TrainError> {
    let rec = OptimizerRecord::load(path).map_err(|e| io(path, format!("{e:?}")))?;
    Ok(optim.load_record(rec))
}

/// Everything besides the tensors that a resumed run needs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct RunState {
    /// Index of the stage in progress (== number of stages when done).
    pub stage: usize,
    /// Steps done in that stage. Patch draws and loss permutations of step k come from
    /// `derive(seed, k)`, so the step is the whole RNG state.
    pub step: usize,
    /// Steps done over all stages.
    pub total_steps: usize,
    pub best_val: Option<f64>,
    pub best_step: Option<usize>,
    /// Validations since the best one (early stopping).
    pub since_best: usize,
    /// Wall-clock seconds spent in earlier sessions of this run.
    pub elapsed: f64,
    /// Module path → parameter id of the optimizer record.
    pub param_ids: BTreeMap<String, u64>,
    /// Hash of the run's options: a resume with different options is refused.
    pub options: String,
}

pub struct CheckpointPaths {
    pub dir: PathBuf,
}

impl CheckpointPaths {
    pub fn weights(&self) -> PathBuf {
        self.dir.join("model.safetensors")
    }
    pub fn optimizer(&self) -> PathBuf {
        self.dir.join("optimizer.bpk")
    }
    pub fn state(&self) -> PathBuf {
        self.dir.join("state.json")
    }
    /// Best-validation weights of stage `k`.
    pub fn best(&self, k: usize) -> PathBuf {
        self.dir.join(format!("best-stage{k}.safetensors"))
    }
}

pub fn save_state(path: &Path, s: &RunState) -> Result<(), TrainError> {
    let json = serde_json::to_vec_pretty(s).map_err(|e| io(path, e))?;
    write_atomically(path, &json)
}

pub fn load_state(path: &Path) -> Result<RunState, TrainError> {
    let bytes = std::fs::read(path).map_err(|e| io(path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| io(path, e))
}

/// Flat list of a model's values (tests and comparisons).
pub fn flat_values(model: &MethodModel) -> Vec<f32> {
    parameters(model).into_iter().flat_map(|(_, _, _, v)| v).collect()
}
