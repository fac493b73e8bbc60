//! The Slurm executor: each node the store lacks becomes one `sbatch` job running
//! `idrex stage run KEY --store URL`, depending (`afterok`) on the jobs of its inputs, with
//! `--kill-on-invalid-dep=yes` so that a failure cancels what depends on it instead of
//! leaving it pending forever.
//!
//! Who computes a node is recorded in the store as a numbered claim (`claims/<key>/<n>`,
//! create-if-absent). A job is submitted held, then claimed, then released; a submitter
//! that loses the claim cancels its held job and depends on the winner's instead, so two
//! submissions of one file compute each node once. A claim whose job has left the queue
//! without the node being stored is a failure: the next submission claims attempt n + 1.
//! The store, never the scheduler's files, says what is done.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use super::config::SlurmConfig;
use super::graph::Graph;
use crate::error::{Error, Result};
use crate::store::{NodeDef, Store, s3::Created};

/// How jobs are submitted.
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    /// Passed to every `sbatch` as they are.
    pub sbatch_args: Vec<String>,
    /// Where the jobs write their output (on a filesystem the nodes share).
    pub log_dir: PathBuf,
    /// The idrex binary the jobs run (on a filesystem the nodes share).
    pub binary: PathBuf,
}

/// A job as recorded in a claim.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Claim {
    pub job: String,
    pub log: PathBuf,
    pub submitted_unix: f64,
}

/// A job's state as `squeue` reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum JobState {
    Pending {
        reason: String,
    },
    Running,
    /// Any other state squeue still shows (completing, suspended, ...).
    Other(String),
}

/// `squeue --noheader --format=%i|%T|%r` output: the jobs still queued or running.
pub fn parse_squeue(text: &str) -> BTreeMap<String, JobState> {
    text.lines()
        .filter_map(|l| {
            let mut f = l.trim().split('|');
            let (id, state, reason) = (f.next()?, f.next()?, f.next().unwrap_or(""));
            let state = match state {
                "PENDING" => JobState::Pending { reason: reason.to_string() },
                "RUNNING" => JobState::Running,
                // Finished: no longer a job anyone can wait for.
                "COMPLETED" | "FAILED" | "CANCELLED" | "TIMEOUT" | "NODE_FAIL" | "PREEMPTED" | "BOOT_FAIL" | "DEADLINE"
                | "OUT_OF_MEMORY" => {
                    return None;
                }
                other => JobState::Other(other.to_string()),
            };
            Some((id.to_string(), state))
        })
        .collect()
}

fn squeue(jobs: Option<&str>) -> Result<BTreeMap<String, JobState>> {
    let mut cmd = Command::new("squeue");
    cmd.args(["--noheader", "--format=%i|%T|%r"]);
    if let Some(j) = jobs {
        cmd.arg(format!("--jobs={j}"));
    }
    let out =
        cmd.output().map_err(|e| Error::Invalid(format!("cannot run squeue ({e}); is Slurm's client installed and SLURM_CONF set?")))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        if jobs.is_some() && err.contains("Invalid job id") {
            return Ok(BTreeMap::new()); // purged from the controller: long finished
        }
        return Err(Error::Invalid(format!("squeue failed: {}", err.trim())));
    }
    Ok(parse_squeue(&String::from_utf8_lossy(&out.stdout)))
}

/// The live jobs: one `squeue` listing, and a fresh question for a job it lacks (submitted
/// by someone else since the listing was taken).
pub struct Queue {
    listing: BTreeMap<String, JobState>,
}

impl Queue {
    pub fn read() -> Result<Queue> {
        Ok(Queue { listing: squeue(None)? })
    }

    pub fn state(&self, job: &str) -> Result<Option<JobState>> {
        if let Some(s) = self.listing.get(job) {
            return Ok(Some(s.clone()));
        }
        Ok(squeue(Some(job))?.remove(job))
    }
}

/// A node's state for `idrex pipeline status`.
#[derive(Debug, Clone, PartialEq)]
pub enum NodeState {
    Stored,
    Queued {
        job: String,
        reason: String,
    },
    Running {
        job: String,
    },
    /// Its last job left the queue without the node being stored.
    Failed {
        job: String,
        log: PathBuf,
    },
    /// Never submitted (or its claim is unreadable).
    Missing,
}

impl NodeState {
    pub fn label(&self) -> &'static str {
        match self {
            NodeState::Stored => "stored",
            NodeState::Queued { .. } => "queued",
            NodeState::Running { .. } => "running",
            NodeState::Failed { .. } => "failed",
            NodeState::Missing => "missing",
        }
    }
}

fn last_claim(store: &Store, key: &str) -> Result<Option<(u32, Option<Claim>)>> {
    Ok(store.last_claim(key)?.map(|(n, text)| (n, serde_json::from_str(&text).ok())))
}

/// What the store and the queue say about `key`. `queue` is None where squeue is not
/// available: a claimed node then reads as queued under its last job.
pub fn node_state(store: &Store, key: &str, queue: Option<&Queue>) -> Result<NodeState> {
    Ok(state_and_attempt(store, key, queue)?.0)
}

/// The node's state and the claim attempt a new submission would make. Both come from one
/// read of the claims: a submission that decided from an older read than its claim could
/// claim the attempt after someone else's fresh one, and both would run.
fn state_and_attempt(store: &Store, key: &str, queue: Option<&Queue>) -> Result<(NodeState, u32)> {
    if store.lookup(key)?.is_some() {
        return Ok((NodeState::Stored, 0));
    }
    let (attempt, claim) = match last_claim(store, key)? {
        None => return Ok((NodeState::Missing, 0)),
        Some((n, None)) => return Ok((NodeState::Missing, n + 1)),
        Some((n, Some(c))) => (n + 1, c),
    };
    let Some(queue) = queue else { return Ok((NodeState::Queued { job: claim.job, reason: "squeue unavailable".into() }, attempt)) };
    let state = match queue.state(&claim.job)? {
        // Held past the moment between claim and release: its submitter died there.
        Some(JobState::Pending { reason })
            if reason.starts_with("JobHeld") && crate::store::now_unix() - claim.submitted_unix > HELD_GRACE_S =>
        {
            NodeState::Failed { job: claim.job, log: claim.log }
        }
        Some(JobState::Running) => NodeState::Running { job: claim.job },
        Some(JobState::Pending { reason }) => NodeState::Queued { job: claim.job, reason },
        Some(JobState::Other(s)) => NodeState::Queued { job: claim.job, reason: s },
        // Gone from the queue: finished, and maybe published since the lookup above.
        None if store.lookup(key)?.is_some() => NodeState::Stored,
        None => NodeState::Failed { job: claim.job, log: claim.log },
    };
    Ok((state, attempt))
}

/// How long a claimed job may stay held before it counts as abandoned (a submitter holds
/// it for the milliseconds between `sbatch` and `scontrol release`).
const HELD_GRACE_S: f64 = 60.0;

/// What submission did with a node.
#[derive(Debug, Clone, PartialEq)]
pub enum Submission {
    Stored,
    /// Already queued or running (by this or another submission).
    Queued {
        job: String,
    },
    Submitted {
        job: String,
    },
}

impl Submission {
    fn job(&self) -> Option<&str> {
        match self {
            Submission::Stored => None,
            Submission::Queued { job } | Submission::Submitted { job } => Some(job),
        }
    }
}

fn run(cmd: &mut Command, what: &str) -> Result<String> {
    let out = cmd.output().map_err(|e| Error::Invalid(format!("cannot run {what} ({e}); is Slurm's client installed?")))?;
    if !out.status.success() {
        return Err(Error::Invalid(format!("{what} failed: {}", String::from_utf8_lossy(&out.stderr).trim())));
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Single quotes for the job's shell.
fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// The `sbatch` arguments of one held job.
fn sbatch_args(
    node: &str,
    key: &str,
    deps: &[&str],
    res: &super::config::Resources,
    store_url: &str,
    log: &Path,
    opts: &SlurmOptions,
) -> Vec<String> {
    let mut a = vec![
        "--parsable".to_string(),
        "--hold".into(),
        format!("--job-name=idrex-{}", node.replace('/', ".")),
        format!("--output={}", log.display()),
    ];
    if !deps.is_empty() {
        a.push(format!("--dependency=afterok:{}", deps.join(":")));
        a.push("--kill-on-invalid-dep=yes".into());
    }
    if let Some(p) = &opts.partition {
        a.push(format!("--partition={p}"));
    }
    if let Some(c) = res.cpus {
        a.push(format!("--cpus-per-task={c}"));
    }
    if let Some(m) = &res.mem {
        a.push(format!("--mem={m}"));
    }
    if let Some(t) = &res.time {
        a.push(format!("--time={t}"));
    }
    if let Some(g) = res.gpus.filter(|&g| g > 0) {
        a.push(format!("--gres=gpu:{g}"));
    }
    a.extend(opts.sbatch_args.iter().cloned());
    a.push(format!("--wrap=exec {} stage run {key} --store {}", quote(&opts.binary.to_string_lossy()), quote(store_url)));
    a
}

/// What node `n`'s job asks for: its kind's resources, and one GPU for a stage planned for
/// CUDA unless they say how many.
pub fn job_resources(n: &super::Node, resources: &SlurmConfig) -> super::config::Resources {
    let mut res = resources.for_kind(n.kind());
    if !n.params.device().is_cpu() && res.gpus.is_none() {
        res.gpus = Some(1);
    }
    res
}

/// Submits every node of `graph` the store lacks and nobody has queued; returns what
/// happened to each node, in the graph's order. Nothing waits for the jobs.
/// Submits every node `store` lacks; each evaluation's job writes `test_set` (a locked test
/// set's mark) into its manifest, as a local run does.
pub fn submit(
    graph: &Graph,
    store: &Store,
    resources: &SlurmConfig,
    opts: &SlurmOptions,
    test_set: Option<&crate::store::TestSetMark>,
) -> Result<Vec<(String, String, Submission)>> {
    std::fs::create_dir_all(&opts.log_dir).map_err(|e| Error::io(&opts.log_dir, e))?;
    let log_dir = std::path::absolute(&opts.log_dir).map_err(|e| Error::io(&opts.log_dir, e))?;
    let queue = Queue::read()?;
    let keys = graph.keys();
    // The jobs may start elsewhere: a local store is named by its absolute path.
    let store_url = match store.url() {
        Some(url) => url.to_string(),
        None => std::path::absolute(store.root()).map_err(|e| Error::io(store.root(), e))?.display().to_string(),
    };
    let mut done: BTreeMap<String, Submission> = BTreeMap::new();
    let mut out = Vec::new();
    for n in &graph.nodes {
        let key = &keys[&n.name];
        let (state, attempt) = state_and_attempt(store, key, Some(&queue))?;
        let s = match state {
            NodeState::Stored => Submission::Stored,
            NodeState::Queued { job, .. } | NodeState::Running { job } => Submission::Queued { job },
            NodeState::Failed { .. } | NodeState::Missing => {
                if let NodeState::Failed { job, .. } = &state {
                    // An abandoned held job would otherwise sit in the queue forever.
                    let _ = Command::new("scancel").arg(job).output();
                }
                let inputs: BTreeMap<String, String> = n.inputs.iter().map(|(role, src)| (role.name(), keys[src].clone())).collect();
                store.put_def(&NodeDef {
                    key: key.clone(),
                    node: n.name.clone(),
                    kind: n.kind().name().to_string(),
                    version: n.kind().version(),
                    params: n.params.to_json(),
                    seed: n.seed,
                    inputs,
                    test_set: test_set.filter(|_| n.kind() == crate::pipeline::stage::StageKind::Eval).cloned(),
                })?;
                let deps: Vec<&str> = n.inputs.iter().filter_map(|(_, src)| done.get(src).and_then(Submission::job)).collect();
                let log = log_dir.join(format!("{}-{}-%j.out", n.name.replace('/', "."), &key[..12]));
                let args = sbatch_args(&n.name, key, &deps, &job_resources(n, resources), &store_url, &log, opts);
                let id = run(Command::new("sbatch").args(&args), "sbatch")?;
                let job = id.split(';').next().unwrap_or(&id).to_string();
                let claim = Claim {
                    job: job.clone(),
                    log: PathBuf::from(log.to_string_lossy().replace("%j", &job)),
                    submitted_unix: crate::store::now_unix(),
                };
                let text = serde_json::to_string(&claim).expect("a claim serialises");
                // The job is held until claimed: on any failure from here it is cancelled, so
                // that no held job is left that nothing points to (or that a claim names
                // but nobody releases).
                let cancel = || {
                    let _ = Command::new("scancel").arg(&job).output();
                };
                let claimed = store.claim(key, attempt, &text).inspect_err(|_| cancel())?;
                // A create whose response was lost and was retried reads as taken: by us.
                let ours =
                    claimed == Created::Yes || matches!(last_claim(store, key), Ok(Some((n, Some(c)))) if n == attempt && c.job == job);
                if ours {
                    run(Command::new("scontrol").args(["release", &job]), "scontrol release").inspect_err(|_| cancel())?;
                    Submission::Submitted { job }
                } else {
                    // Another submission claimed this attempt first: ours never runs.
                    cancel();
                    match last_claim(store, key)? {
                        Some((_, Some(c))) => Submission::Queued { job: c.job },
                        _ => return Err(Error::Invalid(format!("node {}: its claim in {store_url} is unreadable", n.name))),
                    }
                }
            }
        };
        done.insert(n.name.clone(), s.clone());
        out.push((n.name.clone(), key.clone(), s));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::config::Resources;

    #[test]
    fn sbatch_arguments_carry_dependencies_resources_and_a_quoted_command() {
        let opts = SlurmOptions {
            partition: Some("gpu".into()),
            sbatch_args: vec!["--account=rl".into()],
            log_dir: "logs".into(),
            binary: "/shared/it's/idrex".into(),
        };
        let res = Resources { cpus: Some(2), mem: Some("4G".into()), time: None, gpus: Some(1) };
        let a = sbatch_args("drex/ppo/0", "abc", &["11", "12"], &res, "s3://b/p", Path::new("/l/x-%j.out"), &opts);
        for want in [
            "--hold",
            "--job-name=idrex-drex.ppo.0",
            "--dependency=afterok:11:12",
            "--kill-on-invalid-dep=yes",
            "--partition=gpu",
            "--cpus-per-task=2",
            "--mem=4G",
            "--gres=gpu:1",
            "--account=rl",
            r"--wrap=exec '/shared/it'\''s/idrex' stage run abc --store 's3://b/p'",
        ] {
            assert!(a.iter().any(|x| x == want), "{want} missing from {a:?}");
        }
        assert!(!a.iter().any(|x| x.starts_with("--time")));
        let none = sbatch_args("demos", "k", &[], &Resources::default(), "/s", Path::new("/l"), &opts);
        assert!(!none.iter().any(|x| x.starts_with("--dependency")), "{none:?}");
    }

    #[test]
    fn squeue_listing_keeps_live_jobs_only() {
        let q = parse_squeue("12|PENDING|Dependency\n13|RUNNING|None\n14|COMPLETED|None\n15|COMPLETING|None\n");
        assert_eq!(q.get("12"), Some(&JobState::Pending { reason: "Dependency".into() }));
        assert_eq!(q.get("13"), Some(&JobState::Running));
        assert_eq!(q.get("14"), None);
        assert_eq!(q.get("15"), Some(&JobState::Other("COMPLETING".into())));
    }
}
