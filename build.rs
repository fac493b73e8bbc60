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
    // The commit the binary was built from, as semver build metadata (`0.1.0+3f08a66c1d2e`,
    // `.dirty` when the sources differ from it): recorded in every manifest it writes, and
    // shown by `idrex --version` and `exp show`. Empty outside a git checkout.
    for watched in [".git/HEAD", ".git/index", "src", "Cargo.toml"] {
        if Path::new(watched).exists() {
            println!("cargo:rerun-if-changed={watched}");
        }
    }
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).map_or(String::new(), |c| {
        let dirty = git(&["status", "--porcelain", "--untracked-files=no", "--", "src", "build.rs", "Cargo.toml", "Cargo.lock"])
            .is_some_and(|s| !s.is_empty());
        format!("+{c}{}", if dirty { ".dirty" } else { "" })
    });
    println!("cargo:rustc-env=IDREX_BUILD_COMMIT={commit}");
    // The venv python, for tests and benchmarks that compare with Gymnasium.
    let python = std::env::var_os("IDREX_DEFAULT_PYTHON").map(|p| Path::new(&p).to_path_buf());
    println!("cargo:rustc-env=IDREX_BUILD_PYTHON={}", python.map(|p| p.display().to_string()).unwrap_or_default());
}
