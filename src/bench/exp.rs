//! `idrex bench exp`: `exp show` on a generated store of many studies
//! ([`crate::exp::synthetic`]), against reading the same store's manifests alone, which
//! every listing must do (the floor).
use std::time::Instant;

use crate::error::Result;
use crate::exp::{show, studies, synthetic};
use crate::store::Store;

#[derive(Debug, clap::Args)]
pub struct ExpBenchArgs {
    /// Studies in the generated store (each: 5 replicates of BC, D-REX and multi-BC on Hopper).
    #[arg(long, default_value_t = 100)]
    pub studies: usize,
    #[arg(long, default_value_t = 5)]
    pub replicates: usize,
    /// Timed repetitions; the median is reported.
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

pub fn exp_bench(args: &ExpBenchArgs) -> Result<()> {
    let dir = std::env::temp_dir().join(format!("idrex-bench-exp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let manifests = synthetic::write(&dir, args.studies, args.replicates)?;
    let store = Store::open(&dir)?;
    let (mut read, mut full, mut rows) = (Vec::new(), Vec::new(), 0);
    for _ in 0..args.repeats.max(1) {
        let t = Instant::now();
        let m = store.unverified_manifests()?;
        read.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let m2 = store.unverified_manifests()?;
        let table = show::table(&studies(&crate::report::Artifacts::of(m2)), &show::Selection::default());
        full.push(t.elapsed().as_secs_f64());
        rows = table.rows.len();
        drop(m);
    }
    let _ = std::fs::remove_dir_all(&dir);
    let (read, full) = (median(read), median(full));
    println!(
        "exp show on {} studies ({manifests} manifests, {rows} rows): {full:.3} s; reading the manifests alone: {read:.3} s; \
         ratio {:.2} (median of {} runs)",
        args.studies,
        full / read,
        args.repeats.max(1)
    );
    Ok(())
}
