//! Weights are saved as safetensors (loadable from Python with `safetensors.torch.load_file`)
//! next to a small JSON sidecar with everything needed to rebuild the network: dimensions,
//! observation-normalisation statistics, hyper-parameters. Loading checks every tensor's
//! shape against the sidecar before use.
use std::collections::HashMap;
use std::path::Path;

use tch::nn::VarStore;

use crate::error::{Error, Result};

pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Error::file(path, e.to_string()))?;
    std::fs::write(path, text + "\n").map_err(|e| Error::io(path, e))
}

pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::file(path, format!("not a valid sidecar: {e}")))
}

/// Writes the variables of all `stores` (whose names must not collide) to one file.
/// Writes every variable of `stores` to `path`; refuses non-finite weights, which only a
/// diverged training makes and which must never be published.
pub fn save_weights(stores: &[&VarStore], path: &Path) -> Result<()> {
    let mut named: Vec<(String, tch::Tensor)> = stores.iter().flat_map(|vs| vs.variables()).collect();
    named.sort_by(|a, b| a.0.cmp(&b.0));
    if let Some((name, _)) = named.iter().find(|(_, t)| !bool::try_from(t.isfinite().all()).unwrap_or(false)) {
        return Err(Error::Diverged(format!("weight {name} is not finite (training diverged); nothing was saved to {}", path.display())));
    }
    tch::Tensor::write_safetensors(&named, path).map_err(|e| Error::file(path, format!("cannot write weights: {e}")))
}

/// Loads `path` into `stores` after checking that the file has exactly their variables,
/// each with the same shape.
pub fn load_weights(stores: &[&VarStore], path: &Path, sidecar: &Path) -> Result<()> {
    let tensors = tch::Tensor::read_safetensors(path).map_err(|e| Error::file(path, format!("not a readable safetensors file: {e}")))?;
    let mut file: HashMap<String, tch::Tensor> = tensors.into_iter().collect();
    let vars: Vec<(String, tch::Tensor)> = stores.iter().flat_map(|vs| vs.variables()).collect();
    if file.len() != vars.len() {
        return Err(Error::file(
            path,
            format!("has {} tensors, {} implies {}; the two files do not belong together", file.len(), sidecar.display(), vars.len()),
        ));
    }
    for (name, var) in &vars {
        let Some(t) = file.get(name) else {
            return Err(Error::file(
                path,
                format!("has no tensor '{name}', which {} describes; the two files do not belong together", sidecar.display()),
            ));
        };
        if t.size() != var.size() {
            return Err(Error::file(
                path,
                format!(
                    "tensor '{name}' has shape {:?} but {} implies {:?}; the two files do not belong together",
                    t.size(),
                    sidecar.display(),
                    var.size()
                ),
            ));
        }
    }
    tch::no_grad(|| {
        for (name, mut var) in vars {
            let t = file.remove(&name).expect("checked above");
            var.copy_(&t.to_kind(var.kind()));
        }
    });
    Ok(())
}
