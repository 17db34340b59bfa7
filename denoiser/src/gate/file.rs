//! Gate weight files: safetensors with E's tensors (module paths, f32: the file is small) and, in
//! the header, the experts it blends (by name and by the hash of their weight files), its
//! configuration and its provenance. A gate is only meaningful over the experts it was trained
//! with, so loading checks that the expert weight files are the same ones.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;
use serde::{Deserialize, Serialize};

use super::{Expert, GateConfig, GateNet};
use crate::weights::Provenance;

pub mod keys {
    pub const FORMAT: &str = "pixguide.gate.format";
    pub const HEADER: &str = "pixguide.gate";
}
pub const FORMAT_VERSION: &str = "1";

/// Everything in a gate file's header.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GateHeader {
    pub experts: Vec<Expert>,
    /// Identity of each expert's weights (`file_id`: size and FNV-1a hash; OIDN: its version and
    /// settings), in the order of `experts`.
    pub expert_ids: Vec<String>,
    pub widths: Vec<usize>,
    pub provenance: Provenance,
}

/// A loaded gate.
#[derive(Debug)]
pub struct Gate {
    pub net: GateNet,
    pub config: GateConfig,
    pub header: GateHeader,
}

#[derive(Debug, thiserror::Error)]
pub enum GateFileError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
}

/// Size and FNV-1a 64 hash of a file: the identity of an expert's weights (the same identity
/// `pixguide eval` keys its measurements by).
pub fn file_id(path: &Path) -> Result<String, GateFileError> {
    let bytes = std::fs::read(path).map_err(|e| GateFileError::Io { path: path.to_path_buf(), source: e })?;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in &bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    Ok(format!("{}:{h:016x}", bytes.len()))
}

pub fn save(path: &Path, net: &GateNet, header: &GateHeader) -> Result<(), GateFileError> {
    let fmt = |message: String| GateFileError::Format { path: path.to_path_buf(), message };
    let json = serde_json::to_string(header).map_err(|e| fmt(e.to_string()))?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| GateFileError::Io { path: dir.to_path_buf(), source: e })?;
    }
    let mut store = SafetensorsStore::from_file(path).overwrite(true).metadata(keys::FORMAT, FORMAT_VERSION).metadata(keys::HEADER, json);
    net.save_into(&mut store).map_err(|e| fmt(e.to_string()))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o644)).ok();
    }
    Ok(())
}

/// Reads a gate file's header.
pub fn read_header(path: &Path) -> Result<GateHeader, GateFileError> {
    let bytes = std::fs::read(path).map_err(|e| GateFileError::Io { path: path.to_path_buf(), source: e })?;
    header_of(path, &bytes)
}

fn header_of(path: &Path, bytes: &[u8]) -> Result<GateHeader, GateFileError> {
    let fmt = |message: String| GateFileError::Format { path: path.to_path_buf(), message };
    let (_, meta) = safetensors::SafeTensors::read_metadata(bytes).map_err(|e| fmt(format!("not a safetensors file: {e}")))?;
    let meta: HashMap<String, String> = meta.metadata().clone().unwrap_or_default();
    let json = meta.get(keys::HEADER).ok_or_else(|| fmt(format!("no `{}` metadata: not a gate file", keys::HEADER)))?;
    let h: GateHeader = serde_json::from_str(json).map_err(|e| fmt(format!("metadata `{}`: {e}", keys::HEADER)))?;
    if h.experts.is_empty() || h.experts.len() != h.expert_ids.len() || h.widths.is_empty() || h.widths.len() > 6 {
        return Err(fmt("metadata: experts, their ids and the widths do not form a gate".into()));
    }
    if h.widths.iter().any(|&w| w == 0 || w > 1024) {
        return Err(fmt(format!("metadata: widths {:?} out of range", h.widths)));
    }
    Ok(h)
}

pub fn load(path: &Path, device: &Device) -> Result<Gate, GateFileError> {
    let bytes = std::fs::read(path).map_err(|e| GateFileError::Io { path: path.to_path_buf(), source: e })?;
    let header = header_of(path, &bytes)?;
    let config = GateConfig::new(super::feature_channels(header.experts.len()), header.experts.len()).with_widths(header.widths.clone());
    let mut net = config.init(0, device);
    let mut store = SafetensorsStore::from_bytes(Some(bytes)).allow_partial(true).validate(false);
    let fmt = |message: String| GateFileError::Format { path: path.to_path_buf(), message };
    let result = net.load_from(&mut store).map_err(|e| fmt(e.to_string()))?;
    if let Some(e) = result.errors.first() {
        return Err(fmt(format!("{e:?}")));
    }
    if let Some((t, _)) = result.missing.first() {
        return Err(fmt(format!("tensor `{t}` missing from the file")));
    }
    if let Some(t) = result.unused.first() {
        return Err(fmt(format!("tensor `{t}` in the file is not part of the gate")));
    }
    Ok(Gate { net, config, header })
}
