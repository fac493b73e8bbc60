//! Every clone builds and tests exactly its own sources, although all clones on a machine
//! share one cargo target directory (see `dev`): two clones with different sources, the
//! second with files older than the first's build, each get a binary of their own code.
use std::path::Path;
use std::process::Command;

fn git(dir: &Path, args: &[&str]) {
    let out = Command::new("git").args(args).current_dir(dir).output().unwrap();
    assert!(out.status.success(), "git {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn help(clone: &Path) -> String {
    // A developer's environment, not cargo test's: build scripts rerun when variables that
    // cargo sets for tests differ, which would rebuild the dependencies.
    let mut cmd = Command::new(clone.join("dev"));
    cmd.arg("--help").env_clear();
    for var in ["PATH", "HOME", "CARGO_HOME", "RUSTUP_HOME", "IDREX_CACHE", "IDREX_PYTHON", "XDG_CACHE_HOME"] {
        if let Some(v) = std::env::var_os(var) {
            cmd.env(var, v);
        }
    }
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
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
    assert!(help(&a).contains("CLONE-A-MARK"), "clone a runs its own code");
    assert!(!help(&b).contains("CLONE-A-MARK"), "clone b runs its own code, not clone a's newer build");
    assert!(help(&a).contains("CLONE-A-MARK"), "and back");
    std::fs::remove_dir_all(&base).unwrap();
}
