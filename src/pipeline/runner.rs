//! Executes a graph against a store: cached nodes are reused, the rest run in parallel up to
//! `jobs` (each with a share of the cores as its thread budget), each under its key's lock
//! so that concurrent runs on one store compute a node once. A failed node stops its
//! descendants; the others finish.
use std::collections::{BTreeMap, BTreeSet};
use std::sync::mpsc;
use std::time::Instant;

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::Value;

use super::graph::{Graph, Node};
use super::stage::{Inputs, StageCtx, StageKind};
use crate::error::{Error, Result};
use crate::store::{Manifest, Store, TestSetMark, now_unix};

/// A running stage whose amount of work is unknown: a spinner and the time it has taken.
/// (A bar would read 0/0 and look finished.) Messages are cut at the terminal's width.
fn working_style() -> ProgressStyle {
    ProgressStyle::with_template("  {spinner} {prefix:<30} {elapsed:>4} {wide_msg}").expect("template")
}

#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// Found intact in the store.
    Cached,
    Computed {
        wall_s: f64,
    },
    Failed {
        error: String,
        log: std::path::PathBuf,
    },
    /// Not run because an input failed.
    Skipped {
        because: String,
    },
}

#[derive(Debug, Clone)]
pub struct Outcome {
    pub node: String,
    pub key: String,
    pub status: Status,
}

pub struct RunOptions {
    pub jobs: usize,
    /// Nodes to recompute even if stored.
    pub force: Vec<String>,
    pub progress: bool,
    /// Written into the manifest of every evaluation computed ([`super::test_set`]).
    pub test_set: Option<TestSetMark>,
}

pub type StageBody = dyn Fn(&Node, &StageCtx) -> Result<Value> + Sync;

/// Runs one node outside a graph (`idrex stage run KEY`): looked up, computed and
/// published exactly as [`run`] would.
pub fn run_one(
    node: &Node,
    key: &str,
    inputs: Inputs<String>,
    store: &Store,
    (threads, test_set): (usize, Option<&TestSetMark>),
    progress: bool,
    body: &StageBody,
) -> Status {
    let bar = if progress { ProgressBar::new(0) } else { ProgressBar::hidden() };
    bar.set_style(working_style());
    bar.set_prefix(node.name.clone());
    let s = run_node(node, key, inputs, store, (false, test_set), threads, &bar, body);
    bar.finish_and_clear();
    s
}

#[allow(clippy::too_many_arguments)] // one stage run: the node, its key and inputs, and the run's shared context.
fn run_node(
    node: &Node,
    key: &str,
    inputs: Inputs<String>,
    store: &Store,
    (forced, mark): (bool, Option<&TestSetMark>),
    threads: usize,
    bar: &ProgressBar,
    body: &StageBody,
) -> Status {
    let attempt = || -> Result<Status> {
        if !forced && store.lookup(key)?.is_some() {
            return Ok(Status::Cached);
        }
        let _lock = store.lock_or_wait(key, &mut |who| {
            let line = format!("waiting for {}: {who} holds its lock", node.name);
            if bar.is_hidden() { eprintln!("{line}") } else { bar.set_message(line) }
        })?;
        if !forced && store.lookup(key)?.is_some() {
            return Ok(Status::Cached); // published by a concurrent run while we waited
        }
        // A forced node is computed to the side; the stored artifact stays until the new one
        // replaces it.
        // An S3 store's inputs are downloaded into its local cache (and checked) first.
        let input_dirs = inputs.try_map(|k| store.input_dir(k))?;
        let staging = store.stage(key)?;
        let started = now_unix();
        let clock = Instant::now();
        let ctx = StageCtx { seed: node.seed, inputs: input_dirs, out: &staging.dir, threads, progress: bar };
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| body(node, &ctx))).unwrap_or_else(|p| {
            Err(Error::Invalid(format!(
                "the stage panicked: {}",
                p.downcast_ref::<String>().cloned().or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string())).unwrap_or_default()
            )))
        });
        let metrics = match result {
            Ok(m) => m,
            Err(e) => {
                let _ = std::fs::remove_dir_all(&staging.dir);
                return Err(e);
            }
        };
        let wall_s = clock.elapsed().as_secs_f64();
        let manifest = Manifest {
            key: key.to_string(),
            kind: node.kind().name().to_string(),
            version: node.kind().version(),
            node: node.name.clone(),
            params: node.params.to_json(),
            seed: node.seed,
            // The one place a stage's typed inputs become the names a manifest records.
            inputs: inputs.iter().map(|(role, k)| (role.name(), k.clone())).collect(),
            outputs: vec![],
            metrics,
            started_unix: started,
            ended_unix: now_unix(),
            wall_s,
            idrex_version: crate::VERSION.to_string(),
            kernel: Some(node.params.cpu_path()),
            test_set: mark.filter(|_| matches!(node.kind(), StageKind::Eval | StageKind::Probe)).cloned(),
        };
        store.publish(staging, manifest, forced)?;
        Ok(Status::Computed { wall_s })
    };
    match attempt() {
        Ok(s) => s,
        Err(e) => {
            let logs = store.root().join(".logs");
            let _ = std::fs::create_dir_all(&logs);
            let log = logs.join(format!("{}-{}.log", node.name.replace('/', "_"), &key[..12]));
            let text =
                format!("node: {}\nkind: {}\nkey: {key}\nparams: {}\nerror: {e}\n", node.name, node.kind().name(), node.params.to_json());
            let _ = std::fs::write(&log, text);
            Status::Failed { error: e.to_string(), log }
        }
    }
}

/// One line: what the run will do, and how long it should take here (estimated from the
/// store's stage times where it has them, else the reference machine's; see
/// [`crate::pipeline::schedule`]).
pub fn intent(sweep: &super::Sweep, manifests: &[Manifest], g: &Graph, opts: &RunOptions) -> String {
    use super::schedule::{Estimates, makespan};
    let p = &sweep.file;
    let present: std::collections::BTreeSet<&str> = manifests.iter().map(|m| m.key.as_str()).collect();
    let keys = g.keys();
    let todo = |n: &Node| !present.contains(keys[&n.name].as_str()) || opts.force.contains(&n.name);
    let est = Estimates::from_manifests(manifests);
    let kinds: std::collections::BTreeSet<_> = g.nodes.iter().filter(|n| todo(n)).map(|n| n.kind()).collect();
    let (est, source) = if kinds.iter().all(|k| est.measured(*k)) {
        (est, "this store's stage times".to_string())
    } else {
        let speed = super::calibrate::Speed::measure();
        let source = format!(
            "the 2-core reference machine's stage times, scaled by a probe of this processor: matrix products x{:.2}, simulation x{:.2}",
            speed.products, speed.stepping
        );
        (est.on(speed), source)
    };
    let wall = makespan(g, &|n| if todo(n) { est.seconds(n) } else { 0.0 }, opts.jobs.max(1));
    let methods: Vec<&str> = p.spec.methods.iter().map(|m| m.label()).collect();
    let envs: Vec<&str> = p.envs.iter().map(|e| e.name()).collect();
    let mut replicates = if p.is_replicated() { format!(", {} replicates", p.replicates.len()) } else { String::new() };
    if sweep.is_sweep() {
        replicates.push_str(&format!(", {} variants (against `{}`)", sweep.variants.len(), sweep.baseline));
    }
    let to_compute = g.nodes.iter().filter(|n| todo(n)).count();
    format!(
        "{}: {} on {}, {} RL runs per method, K = {}{replicates}: {} stages, {to_compute} to compute; about {} with {} (from {source})",
        p.name,
        methods.join(", "),
        envs.join(", "),
        p.spec.seeds.len(),
        p.spec.iterations,
        g.nodes.len(),
        minutes(wall),
        jobs_phrase(opts.jobs)
    )
}

/// "1 job", "2 jobs".
pub fn jobs_phrase(jobs: usize) -> String {
    if jobs == 1 { "1 job".into() } else { format!("{jobs} jobs") }
}

/// A duration for people: seconds under a minute, else whole minutes.
pub fn minutes(seconds: f64) -> String {
    if seconds < 60.0 { format!("{:.0} s", seconds.max(0.0)) } else { format!("{:.0} min", seconds / 60.0) }
}

/// What a run knows while it runs: each ended stage's status, the running stages' cores and
/// start times, and the seconds taken and estimated by the stages computed so far (how far
/// off the estimates are on this machine today).
struct Board<'g> {
    graph: &'g Graph,
    keys: BTreeMap<String, String>,
    /// Stages whose stored artifact is reused (present and not forced).
    reused: BTreeSet<String>,
    estimates: super::schedule::Estimates,
    status: BTreeMap<String, Status>,
    running: BTreeMap<String, usize>,
    since: BTreeMap<String, Instant>,
    /// Per stage kind, the seconds its computed stages took and were estimated to take.
    taken: BTreeMap<StageKind, (f64, f64)>,
}

impl<'g> Board<'g> {
    /// Marks the descendants of failures skipped; returns how many it marked.
    fn skip_descendants_of_failures(&mut self) -> u64 {
        let mut skipped = 0;
        for n in &self.graph.nodes {
            if self.status.contains_key(&n.name) {
                continue;
            }
            let failed = |i: &String| matches!(self.status.get(i), Some(Status::Failed { .. } | Status::Skipped { .. }));
            if let Some((_, bad)) = n.inputs.iter().find(|(_, i)| failed(i)) {
                self.status.insert(n.name.clone(), Status::Skipped { because: bad.clone() });
                skipped += 1;
            }
        }
        skipped
    }

    /// The stages whose inputs are all done, most estimated work behind them first (stable:
    /// equal estimates keep the graph's order).
    fn ready(&self, priority: &BTreeMap<String, f64>) -> Vec<&'g Node> {
        let done = |i: &String| matches!(self.status.get(i), Some(Status::Cached | Status::Computed { .. }));
        let mut ready: Vec<&Node> = self
            .graph
            .nodes
            .iter()
            .filter(|n| !self.status.contains_key(&n.name) && !self.running.contains_key(&n.name))
            .filter(|n| n.inputs.iter().all(|(_, i)| done(i)))
            .collect();
        ready.sort_by(|a, b| priority[&b.name].total_cmp(&priority[&a.name]));
        ready
    }

    /// How far off this run's stages of `kind` were: taken over estimated, once half a minute
    /// of that kind's estimated work has run, else 1. Per kind, so that fast early stages
    /// (demonstrations, BC) never shrink the estimate of kinds that have not run yet (PPO).
    fn scale(&self, kind: StageKind) -> f64 {
        match self.taken.get(&kind) {
            Some(&(taken, estimated)) if estimated > 30.0 => (taken / estimated).clamp(0.25, 4.0),
            _ => 1.0,
        }
    }

    /// How long the rest should take with `jobs`, each estimate scaled by its kind's
    /// [`Board::scale`].
    fn left(&self, jobs: usize) -> f64 {
        let cost = |n: &Node| {
            if self.status.contains_key(&n.name) || self.reused.contains(&n.name) {
                0.0
            } else {
                let est = self.estimates.seconds(n) * self.scale(n.kind());
                self.since.get(&n.name).map_or(est, |t| (est - t.elapsed().as_secs_f64()).max(0.0))
            }
        };
        super::schedule::makespan(self.graph, &cost, jobs)
    }

    /// Records a stage's end; returns the new "about N min left".
    fn ended(&mut self, name: &str, s: Status, jobs: usize) -> String {
        self.running.remove(name);
        if let (Status::Computed { wall_s }, Some(n)) = (&s, self.graph.get(name)) {
            let t = self.taken.entry(n.kind()).or_default();
            t.0 += wall_s;
            t.1 += self.estimates.seconds(n);
        }
        self.since.remove(name);
        self.status.insert(name.to_string(), s);
        format!("about {} left", minutes(self.left(jobs)))
    }
}

/// The cores the `starting` stages share: what the running ones leave, no more than other
/// processes leave idle where a stage could use several, and a thread each where more jobs
/// than cores were asked for.
fn free_cores(starting: &[&Node], in_use: usize, jobs: usize, cores: usize) -> usize {
    let mut free = cores.saturating_sub(in_use);
    if starting.iter().any(|n| n.kind().parallel()) && free > starting.len() {
        free = free.min(super::cores::idle_elsewhere().unwrap_or(free).max(starting.len()));
    }
    if jobs > cores { free.max(starting.len()) } else { free }
}

/// The line an ended stage leaves above the bars: what happened and how long it took.
fn ended_line(name: &str, s: &Status) -> Option<String> {
    match s {
        Status::Failed { error, .. } => Some(format!("  failed    {name}: {error}")),
        Status::Computed { wall_s } => Some(format!("  computed  {name} ({wall_s:.1} s)")),
        Status::Cached => Some(format!("  reused    {name}")),
        Status::Skipped { .. } => None,
    }
}

pub fn run(graph: &Graph, store: &Store, opts: &RunOptions, body: &StageBody) -> Result<Vec<Outcome>> {
    if let Some(f) = opts.force.iter().find(|f| graph.get(f).is_none()) {
        let names: Vec<&str> = graph.nodes.iter().map(|n| n.name.as_str()).collect();
        return Err(Error::Invalid(format!("--force {f}: no such node; the nodes are {}", names.join(", "))));
    }
    let _using = store.in_use()?;
    store.clean_stale_staging();
    let keys = graph.keys();
    // Critical path first: the ready stage with the most estimated work behind it starts.
    // Ordering only, so the manifests are read without re-hashing their outputs.
    let written = store.unverified_manifests()?;
    let present: BTreeSet<&str> = written.iter().map(|m| m.key.as_str()).collect();
    let reused: BTreeSet<String> = graph
        .nodes
        .iter()
        .filter(|n| present.contains(keys[&n.name].as_str()) && !opts.force.contains(&n.name))
        .map(|n| n.name.clone())
        .collect();
    let estimates = super::schedule::Estimates::from_manifests(&written);
    let priority = super::schedule::remaining(graph, &|n| if reused.contains(&n.name) { 0.0 } else { estimates.seconds(n) });
    let (jobs, cores) = (opts.jobs.max(1), std::thread::available_parallelism().map_or(1, |n| n.get()));
    let multi = MultiProgress::with_draw_target(if opts.progress { ProgressDrawTarget::stderr() } else { ProgressDrawTarget::hidden() });
    let overall = multi.add(ProgressBar::new(graph.nodes.len() as u64));
    overall.set_style(ProgressStyle::with_template("[{elapsed_precise}] {bar:30} {pos}/{len} stages {wide_msg}").expect("template"));
    let stage_style = working_style();
    let mut board = Board {
        graph,
        keys,
        reused,
        estimates,
        status: BTreeMap::new(),
        running: BTreeMap::new(),
        since: BTreeMap::new(),
        taken: BTreeMap::new(),
    };
    overall.set_message(format!("about {} left", minutes(board.left(jobs))));
    let (tx, rx) = mpsc::channel::<(String, Status)>();
    std::thread::scope(|scope| {
        loop {
            overall.inc(board.skip_descendants_of_failures());
            let starting: Vec<&Node> = board.ready(&priority).into_iter().take(jobs.saturating_sub(board.running.len())).collect();
            let free = free_cores(&starting, board.running.values().sum(), jobs, cores);
            for (n, threads) in starting.iter().zip(super::cores::grants(&starting, free)).filter(|(_, t)| *t > 0) {
                let n = *n;
                tracing::debug!(stage = %n.name, threads, "starting");
                board.running.insert(n.name.clone(), threads);
                board.since.insert(n.name.clone(), Instant::now());
                let key = board.keys[&n.name].clone();
                let inputs = n.inputs.map(|src| board.keys[src].clone());
                let forced = opts.force.contains(&n.name);
                let bar = multi.insert_before(&overall, ProgressBar::new(0));
                bar.set_style(stage_style.clone());
                bar.set_prefix(n.name.clone());
                bar.enable_steady_tick(std::time::Duration::from_millis(200));
                let tx = tx.clone();
                scope.spawn(move || {
                    let s = run_node(n, &key, inputs, store, (forced, opts.test_set.as_ref()), threads, &bar, body);
                    bar.finish_and_clear();
                    let _ = tx.send((n.name.clone(), s));
                });
            }
            if board.running.is_empty() {
                break;
            }
            let (name, s) = rx.recv().expect("a worker reports before it exits");
            let line = ended_line(&name, &s);
            let eta = board.ended(&name, s, jobs);
            overall.inc(1);
            overall.set_message(eta.clone());
            // Without a terminal, the line goes to the log with the bar's figures.
            if let Some(line) = line.filter(|_| opts.progress) {
                if multi.is_hidden() {
                    let elapsed = minutes(overall.elapsed().as_secs_f64());
                    eprintln!("{line}  [{}/{} stages, {elapsed} elapsed, {eta}]", overall.position(), graph.nodes.len());
                } else {
                    multi.println(line).ok().unwrap_or(())
                }
            }
        }
    });
    overall.finish_and_clear();
    let Board { mut status, keys, .. } = board;
    Ok(graph
        .nodes
        .iter()
        .map(|n| Outcome { node: n.name.clone(), key: keys[&n.name].clone(), status: status.remove(&n.name).expect("every node ends") })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::stage::idrex::action_noise;
    use crate::pipeline::stage::{ActionNoiseInputs, Params};

    /// A test stage, run by [`body`] instead of a stage kind's code: it writes its value plus
    /// its inputs' values. It borrows the shape of a kind whose inputs are a plain series (its
    /// parameters carry the value as `rollouts_per_level`, so that it is in the key), and
    /// its seed says how long it sleeps and whether it fails.
    fn node(name: &str, value: i64, inputs: &[&str], sleep_ms: u64, fail: bool) -> Node {
        Node {
            name: name.into(),
            params: Params::ActionNoiseRollouts(action_noise::Params {
                env: crate::env::EnvId::Hopper,
                sigmas: vec![],
                noise: Default::default(),
                rollouts_per_level: value as usize,
                horizon: Default::default(),
            }),
            seed: 2 * sleep_ms + fail as u64,
            inputs: Inputs::ActionNoiseRollouts(ActionNoiseInputs { policies: inputs.iter().map(|s| s.to_string()).collect() }),
        }
    }

    fn body(n: &Node, ctx: &StageCtx) -> Result<Value> {
        let (Params::ActionNoiseRollouts(p), Inputs::ActionNoiseRollouts(inputs)) = (&n.params, &ctx.inputs) else {
            unreachable!("test nodes are of one shape")
        };
        std::thread::sleep(std::time::Duration::from_millis(n.seed / 2));
        if n.seed % 2 == 1 {
            return Err(Error::Invalid("this test stage was asked to fail".into()));
        }
        let mut v = p.rollouts_per_level as i64;
        for dir in &inputs.policies {
            let path = dir.join("value.txt");
            v += std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?.trim().parse::<i64>().unwrap();
        }
        std::fs::write(ctx.out.join("value.txt"), v.to_string()).map_err(|e| Error::io(ctx.out, e))?;
        Ok(serde_json::json!({ "value": v }))
    }

    /// Fast early stages of one kind never shrink what the stages of another kind, not run
    /// yet, are known to cost: after a 50x-too-fast first stage, the rest is still estimated
    /// at least at the unrun stage's own estimate (issue 78: "8 min left" after the
    /// demonstrations with every PPO run still to come).
    #[test]
    fn the_estimate_left_never_falls_below_the_unrun_kinds_cost() {
        let demos = Node {
            name: "later".into(),
            params: Params::DemosImport(crate::pipeline::stage::demos::ImportParams {
                env: crate::env::EnvId::Hopper,
                path: "d.npz".into(),
                sha256: "0".repeat(64),
            }),
            seed: 0,
            inputs: Inputs::DemosImport(Default::default()),
        };
        let mut first = node("first", 1000, &[], 0, false);
        if let Params::ActionNoiseRollouts(p) = &mut first.params {
            p.sigmas = vec![0.5];
        }
        let g = Graph { nodes: vec![first.clone(), demos.clone()] };
        let estimates = super::super::schedule::Estimates::default();
        let mut board = Board {
            graph: &g,
            keys: g.keys(),
            reused: BTreeSet::new(),
            estimates: estimates.clone(),
            status: BTreeMap::new(),
            running: BTreeMap::new(),
            since: BTreeMap::new(),
            taken: BTreeMap::new(),
        };
        let before = board.left(1);
        let first_est = estimates.seconds(&first);
        assert!(first_est > 30.0, "a first stage long enough to calibrate on: {first_est}");
        board.ended("first", Status::Computed { wall_s: first_est / 50.0 }, 1);
        assert_eq!(board.scale(first.kind()), 0.25);
        assert_eq!(board.left(1), estimates.seconds(&demos), "the unrun kind keeps its estimate");
        assert!(board.left(1) < before);
    }

    fn opts(force: &[&str]) -> RunOptions {
        RunOptions { jobs: 2, force: force.iter().map(|s| s.to_string()).collect(), progress: false, test_set: None }
    }

    fn value(store: &Store, o: &Outcome) -> String {
        std::fs::read_to_string(store.dir(&o.key).join("value.txt")).unwrap()
    }

    #[test]
    fn caches_recomputes_forced_nodes_and_stops_descendants_of_failures() {
        let root = std::env::temp_dir().join(format!("idrex-runner-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let store = Store::open(&root).unwrap();
        let g = Graph {
            nodes: vec![
                node("a", 1, &[], 0, false),
                node("b", 10, &["a"], 50, false),
                node("c", 100, &["a"], 50, false),
                node("d", 1000, &["b", "c"], 0, false),
            ],
        };
        let out = run(&g, &store, &opts(&[]), &body).unwrap();
        assert!(out.iter().all(|o| matches!(o.status, Status::Computed { .. })));
        assert_eq!(value(&store, &out[3]), "1112");
        let again = run(&g, &store, &opts(&[]), &body).unwrap();
        assert!(again.iter().all(|o| o.status == Status::Cached));
        let forced = run(&g, &store, &opts(&["c"]), &body).unwrap();
        let computed: Vec<&str> = forced.iter().filter(|o| matches!(o.status, Status::Computed { .. })).map(|o| o.node.as_str()).collect();
        assert_eq!(computed, vec!["c"]);
        assert!(run(&g, &store, &opts(&["nope"]), &body).unwrap_err().to_string().contains("no such node"));

        // A failing stage: its descendants are skipped, its siblings finish, its log exists.
        let mut bad = g.clone();
        bad.nodes[1] = node("b", 11, &["a"], 0, true);
        bad.nodes[2] = node("c", 101, &["a"], 0, false);
        let out = run(&bad, &store, &opts(&[]), &body).unwrap();
        assert!(matches!(&out[1].status, Status::Failed { log, .. } if log.exists()));
        assert!(matches!(out[2].status, Status::Computed { .. }));
        assert_eq!(out[3].status, Status::Skipped { because: "b".into() });
        assert!(!store.dir(&out[1].key).exists(), "nothing of the failed stage is published");

        // A forced recomputation that fails leaves the stored artifact as it was.
        let failing = |n: &Node, ctx: &StageCtx| if n.name == "c" { Err(Error::Invalid("boom".into())) } else { body(n, ctx) };
        let before = value(&store, &out[2]);
        let forced = run(&bad, &store, &opts(&["c"]), &failing).unwrap();
        assert!(matches!(forced[2].status, Status::Failed { .. }));
        assert_eq!(value(&store, &out[2]), before);
        assert!(store.check(&out[2].key).is_ok());
        std::fs::remove_dir_all(&root).unwrap();
    }
}
