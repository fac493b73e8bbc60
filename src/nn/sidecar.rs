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

/// A sidecar's text parsed; `path` names it in a refusal.
pub fn parse_json<T: serde::de::DeserializeOwned>(path: &Path, text: &str) -> Result<T> {
    serde_json::from_str(text).map_err(|e| Error::file(path, format!("not a valid sidecar: {e}")))
}

/// The parameters of an MLP with these layer sizes (weights and biases), if they fit a u64.
pub fn mlp_parameters(sizes: &[usize]) -> Option<u64> {
    sizes.windows(2).try_fold(0u64, |n, w| {
        let (i, o) = (u64::try_from(w[0]).ok()?, u64::try_from(w[1]).ok()?);
        n.checked_add(i.checked_mul(o)?.checked_add(o)?)
    })
}

/// Refuses a sidecar that describes more parameters than its weights file can hold (4 bytes
/// each, f32): a hostile or mismatched sidecar must not make idrex build a network first.
pub fn check_size(sidecar: &Path, parameters: Option<u64>, weights_bytes: u64) -> Result<()> {
    match parameters {
        Some(p) if p.saturating_mul(4) <= weights_bytes => Ok(()),
        p => Err(Error::file(
            sidecar,
            format!(
                "describes {} parameters, more than the {weights_bytes}-byte weights file beside it holds; the two files do not belong together",
                p.map_or("uncountably many".to_string(), |p| p.to_string())
            ),
        )),
    }
}

/// The size of a weights file, to check a sidecar against before anything is built.
pub fn weights_bytes(path: &Path) -> Result<u64> {
    Ok(std::fs::metadata(path).map_err(|e| Error::io(path, e))?.len())
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
