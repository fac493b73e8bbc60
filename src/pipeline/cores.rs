//! How many cores each stage is granted: the runner's budget of compute threads.
//!
//! Every starting stage gets one core while any is free; the cores left over go to the
//! stages that use more ([`StageKind::parallel`](super::stage::StageKind::parallel)), but
//! only cores that other processes leave idle: BC's two lanes on a machine whose cores
//! another process keeps busy ran at half the speed of one lane (274 against 529
//! iterations/s, `idrex bench learners` beside two busy loops), as every step waits for the
//! lane that was descheduled. Outputs never depend on the grants.
use std::time::Duration;

use super::graph::Node;

/// The cores each of `starting` (in priority order) is granted when `free` cores are not
/// held by running stages: one each while there are free ones (the others wait: granted
/// none), and what is left over to the stages that can use more, shared evenly. So the
/// stages' compute threads never add up to more than the cores.
pub fn grants(starting: &[&Node], free: usize) -> Vec<usize> {
    let mut grants: Vec<usize> = (0..starting.len()).map(|i| usize::from(i < free)).collect();
    let mut spare = free.saturating_sub(starting.len());
    let parallel: Vec<usize> = (0..starting.len()).filter(|&i| grants[i] > 0 && starting[i].kind().parallel()).collect();
    for (j, &i) in parallel.iter().enumerate() {
        let share = spare.div_ceil(parallel.len() - j);
        grants[i] += share;
        spare -= share;
    }
    grants
}

/// How long [`idle_elsewhere`] watches the machine.
const WINDOW: Duration = Duration::from_millis(100);

/// How many of the CPUs this process may run on are idle, not counting this process's own
/// use of them, watched for `WINDOW`: the CPUs' busy time (`/proc/stat`) less this
/// process's CPU time. None where `/proc` cannot tell (not Linux).
pub fn idle_elsewhere() -> Option<usize> {
    let cpus = allowed_cpus()?;
    let (busy0, own0) = (busy_ns(&cpus)?, own_ns()?);
    let start = std::time::Instant::now();
    std::thread::sleep(WINDOW);
    let (busy1, own1) = (busy_ns(&cpus)?, own_ns()?);
    let elapsed = start.elapsed().as_nanos() as f64;
    let others = ((busy1 - busy0) - (own1 - own0)).max(0.0) / elapsed;
    tracing::debug!(cpus = cpus.len(), others, "CPU use by other processes");
    Some(cpus.len().saturating_sub(others.round() as usize))
}

/// The CPUs in this process's affinity mask (`Cpus_allowed_list: 0-3,8`).
fn allowed_cpus() -> Option<Vec<usize>> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let list = status.lines().find_map(|l| l.strip_prefix("Cpus_allowed_list:"))?.trim();
    let mut cpus = Vec::new();
    for part in list.split(',') {
        match part.split_once('-') {
            Some((a, b)) => cpus.extend(a.parse::<usize>().ok()?..=b.parse::<usize>().ok()?),
            None => cpus.push(part.parse().ok()?),
        }
    }
    Some(cpus)
}

/// Busy time of `cpus` so far, in ns: all but idle and iowait (`/proc/stat` counts ticks of
/// 1/100 s on Linux).
fn busy_ns(cpus: &[usize]) -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let mut busy = 0.0;
    for line in stat.lines().filter(|l| l.starts_with("cpu") && !l.starts_with("cpu ")) {
        let mut fields = line.split_whitespace();
        let cpu: usize = fields.next()?.strip_prefix("cpu")?.parse().ok()?;
        if !cpus.contains(&cpu) {
            continue;
        }
        let ticks: Vec<f64> = fields.take(8).map(|f| f.parse().unwrap_or(0.0)).collect();
        busy += ticks.iter().sum::<f64>() - ticks.get(3).unwrap_or(&0.0) - ticks.get(4).unwrap_or(&0.0);
    }
    Some(busy * 1e7)
}

/// CPU time of this process so far, in ns, its ended threads' included (`/proc/self/stat`,
/// in ticks of 1/100 s). Not the sum over `/proc/self/task`: a stage thread that ended
/// during the window would count as another process.
fn own_ns() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // After the command name (in parentheses, and free to hold spaces): field 3 onwards.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) * 1e7)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::stage::{self, Params};

    #[test]
    fn cores_go_one_per_stage_then_to_the_stages_that_use_more() {
        let bc = |name: &str| Node {
            name: name.into(),
            params: Params::Bc(stage::bc::BcParams { env: crate::env::EnvId::Hopper, bc: Default::default(), device: Default::default() }),
            seed: 0,
            inputs: stage::Inputs::Bc(stage::BcInputs { demos: "demos".into() }),
        };
        let t = Node {
            name: "t".into(),
            params: Params::Demos(stage::demos::DemosParams {
                env: crate::env::EnvId::Hopper,
                episodes: 1,
                acting: Default::default(),
                noise_scale: 1.0,
            }),
            seed: 0,
            inputs: stage::Inputs::Demos(stage::DemosInputs { policy: "demonstrator".into() }),
        };
        let (a, b) = (bc("a"), bc("b"));
        // Alone on an idle machine, BC gets every core; beside another stage, its share.
        assert_eq!(grants(&[&a], 2), [2]);
        assert_eq!(grants(&[&a, &t], 2), [1, 1]);
        assert_eq!(grants(&[&t, &a], 4), [1, 3]);
        assert_eq!(grants(&[&a, &b, &t], 8), [4, 3, 1]);
        // Stages that use one thread get one; with no core free, a stage waits.
        assert_eq!(grants(&[&t], 4), [1]);
        assert_eq!(grants(&[&a, &t], 1), [1, 0]);
        assert_eq!(grants(&[&a], 0), [0]);
    }

    #[test]
    #[cfg(target_os = "linux")]
    fn another_process_keeps_a_core_and_our_own_threads_do_not() {
        let idle = idle_elsewhere().expect("Linux has /proc/stat and /proc/self/status");
        let cpus = allowed_cpus().unwrap().len();
        // Our own busy threads, one per CPU, are not other processes.
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let spinners: Vec<_> = (0..cpus)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                        std::hint::spin_loop();
                    }
                })
            })
            .collect();
        let with_own = idle_elsewhere().unwrap();
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        spinners.into_iter().for_each(|t| t.join().unwrap());
        // A busy child process is. (Other tests run beside this one, so compare loosely.)
        let mut child = std::process::Command::new("sh").args(["-c", "while :; do :; done"]).spawn().unwrap();
        std::thread::sleep(Duration::from_millis(50));
        let with_child = idle_elsewhere().unwrap();
        child.kill().unwrap();
        child.wait().unwrap();
        assert!(idle <= cpus);
        // Counted as others they would leave none idle; allow other tests' noise.
        assert!(2 * with_own >= cpus, "our own {cpus} spinning threads left {with_own} of {cpus} CPUs idle");
        assert!(with_child < cpus, "a busy process beside us, yet all {cpus} CPUs idle");
    }
}
