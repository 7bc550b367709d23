//! Neural signed distances as files: one JSON document (the map's name, layer sizes,
//! input scale, flat parameters), written atomically, shape-checked when read.

use std::path::Path;

use super::{StoreError, invalid};
use crate::task::neural_sdf::NeuralSdf;

/// Saves `net` to `path`; refuses to replace a file unless `force`.
pub fn save(net: &NeuralSdf, path: &Path, force: bool) -> Result<(), StoreError> {
    let json = serde_json::to_string(net).map_err(|e| invalid(path, e.to_string()))?;
    super::save_file(path, json.as_bytes(), force)
}

/// Loads a network saved by [`save`], checking its shape.
pub fn load(path: &Path) -> Result<NeuralSdf, StoreError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| invalid(path, format!("cannot read the neural SDF: {e}")))?;
    let net: NeuralSdf = serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
    net.check().map_err(|m| invalid(path, m))?;
    Ok(net)
}
