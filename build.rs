//! Bakes the run-time library paths of the bootstrap environment into every binary and test
//! (rpath), so that `idrex` runs without LD_LIBRARY_PATH, and records where gymnasium's MuJoCo
//! model files were at build time as the default asset directory.
//!
//! Every clone on a machine shares one cargo target directory (the dependency build), and
//! cargo's fingerprint of this crate compares file times, so a clone whose files are older
//! than another clone's build would reuse that build. `IDREX_CLONE` (the clone's path, set
//! by the `.cargo/config.toml` that scripts/bootstrap.sh writes) is tracked here: building
//! in another clone reruns this script, and with it the idrex crate's compilation (only it).
use std::path::Path;

fn main() {
    for var in ["LIBTORCH", "MUJOCO_DYNAMIC_LINK_DIR", "IDREX_DEFAULT_ASSETS", "IDREX_DEFAULT_PYTHON", "IDREX_CLONE"] {
        println!("cargo:rerun-if-env-changed={var}");
    }
    let canon = |p: &Path| std::fs::canonicalize(p).ok();
    if let Some(lib) = std::env::var_os("LIBTORCH").and_then(|t| canon(&Path::new(&t).join("lib"))) {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    }
    if let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR").and_then(|d| canon(Path::new(&d))) {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
    }
    let assets = std::env::var_os("IDREX_DEFAULT_ASSETS").and_then(|d| canon(Path::new(&d)));
    println!("cargo:rustc-env=IDREX_BUILD_ASSETS={}", assets.map(|p| p.display().to_string()).unwrap_or_default());
    // The venv python, for tests and benchmarks that compare with Gymnasium.
    let python = std::env::var_os("IDREX_DEFAULT_PYTHON").map(|p| Path::new(&p).to_path_buf());
    println!("cargo:rustc-env=IDREX_BUILD_PYTHON={}", python.map(|p| p.display().to_string()).unwrap_or_default());
}
