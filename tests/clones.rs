//! Every clone builds and tests exactly its own sources, through `./dev` or plain cargo,
//! although all clones on a machine share one cargo target directory (see `build.rs`): two
//! clones with different sources, the second with files older than the first's build, each
//! get a binary of their own code.
use std::path::Path;
use std::process::Command;

fn git(dir: &Path, args: &[&str]) {
    let out = Command::new("git").args(args).current_dir(dir).output().unwrap();
    assert!(out.status.success(), "git {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// A developer's environment, not cargo test's: build scripts rerun when variables that
/// cargo sets for tests differ, which would rebuild the dependencies.
fn developer(program: &Path, dir: &Path) -> Command {
    let mut cmd = Command::new(program);
    cmd.current_dir(dir).env_clear();
    for var in ["PATH", "HOME", "CARGO_HOME", "RUSTUP_HOME", "IDREX_CACHE", "IDREX_PYTHON", "XDG_CACHE_HOME"] {
        if let Some(v) = std::env::var_os(var) {
            cmd.env(var, v);
        }
    }
    cmd
}

fn stdout(mut cmd: Command) -> String {
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{cmd:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `idrex --help` as `./dev --help` builds and runs it.
fn dev_help(clone: &Path) -> String {
    let mut cmd = developer(&clone.join("dev"), clone);
    cmd.arg("--help");
    stdout(cmd)
}

/// `idrex --help` from plain `cargo build --release` (after the set-up, which writes the
/// clone's .cargo/config.toml), run from the target directory cargo built it in.
fn cargo_help(clone: &Path) -> String {
    stdout(developer(&clone.join("scripts/bootstrap.sh"), clone));
    let mut build = developer(Path::new("cargo"), clone);
    build.args(["build", "--release", "--quiet", "--bin", "idrex"]);
    stdout(build);
    let mut dir = developer(Path::new("cargo"), clone);
    dir.args(["metadata", "--format-version", "1", "--no-deps"]);
    let meta: serde_json::Value = serde_json::from_str(&stdout(dir)).unwrap();
    let bin = Path::new(meta["target_directory"].as_str().unwrap()).join("release/idrex");
    let mut help = developer(&bin, clone);
    help.arg("--help");
    stdout(help)
}

#[test]
fn each_clone_builds_its_own_sources() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let base = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("clones-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    std::fs::create_dir_all(&base).unwrap();
    let (a, b) = (base.join("a"), base.join("b"));
    for c in [&a, &b] {
        git(&base, &["clone", "--quiet", "--no-hardlinks", repo.to_str().unwrap(), c.to_str().unwrap()]);
    }
    // Clone a differs in one string; clone b's files are all older than a's build will be.
    let cli = a.join("src/cli/mod.rs");
    let text = std::fs::read_to_string(&cli).unwrap();
    let marked = text.replace("Reward learning from automatically ranked demonstrations", "CLONE-A-MARK Reward learning");
    assert_ne!(marked, text, "the marker string is in src/cli/mod.rs");
    std::fs::write(&cli, marked).unwrap();
    let old = Command::new("find")
        .arg(&b)
        .args(["-path", "*/.git", "-prune", "-o", "-type", "f", "-exec", "touch", "-d", "2001-01-01", "{}", "+"])
        .status()
        .unwrap();
    assert!(old.success());
    assert!(dev_help(&a).contains("CLONE-A-MARK"), "clone a runs its own code");
    assert!(!cargo_help(&b).contains("CLONE-A-MARK"), "plain cargo in clone b builds its own code, not clone a's newer build");
    assert!(cargo_help(&a).contains("CLONE-A-MARK"), "and back, with plain cargo");
    assert!(!dev_help(&b).contains("CLONE-A-MARK"), "and ./dev in clone b");
    std::fs::remove_dir_all(&base).unwrap();
    // Leave the shared build as this clone builds it: the suite's later tests, and a user's
    // `target/release/idrex`, run this clone's code (issue 43).
    assert!(!dev_help(repo).contains("CLONE-A-MARK"));
}
