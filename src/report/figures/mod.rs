//! The report's figures, as SVG and PNG, drawn with plotters from the store's manifests, per
//! (environment, pipeline):
//! - `degradation`: return against noise level for every rollout set a reward was trained
//!   on, mean ± std, with the demonstrations' mean ± std (the paper's Figures 5, 7, 9, 10);
//! - `reward-<method>`: predicted against true return for the demonstrations, the training
//!   set and unseen evaluation rollouts, each set's Pearson correlation in the legend
//!   (Figures 6, 8, 11);
//! - `ppo`: true and learned (ensemble mean) return of every checkpoint against PPO's steps,
//!   one line per run, coloured by method;
//! - `final`: the five methods under the three protocols, bars with 95 % bootstrap intervals,
//!   with the demonstrations' average;
//! - `clones`: multi-BC's clones against their sources (`figures/clones.rs`);
//! - per (environment, study) with several replicates, `intervals` and `profile`
//!   (`figures/studies.rs`).
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

mod clones;
mod runs;
mod studies;

use super::Artifacts;
use super::studies::AggregateRow;
use super::{Protocol, ProtocolRow};
use crate::error::{Error, Result};
use crate::pipeline::Method;
use crate::pipeline::role::{Role, Series};
use crate::pipeline::stage::{DegradationLevel, Metrics, Typed};
use crate::stats::pearson;
use crate::store::Manifest;
use runs::{Curve, Degradation, FinalBars, PpoCurves, RewardScatter, Runs};

const SIZE: (u32, u32) = (960, 640);
const FONT: &str = "sans-serif";
/// The minor grid's lines per major division: none. Its faint lines were 60 % of every SVG's
/// bytes (4.9 MB of analysis/) and the major grid at each label guides the eye. Zero is safe
/// only on f64 axes, as every axis here is: plotters' integer key points never end on zero.
const MINOR_GRID: usize = 0;

/// Which files a figure is written as: `<stem>.svg`, `<stem>.png` or both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FigureFormats {
    Svg,
    Png,
    #[default]
    Both,
}

impl FigureFormats {
    fn svg(self) -> bool {
        self != FigureFormats::Png
    }
    fn png(self) -> bool {
        self != FigureFormats::Svg
    }
}

/// Which tables of a replicated study get their own figures (the study's intervals and
/// profile are always drawn).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ReplicateFigures {
    /// Every replicate's table.
    #[default]
    All,
    /// Replicate 0's table only: a report over many replicates stays readable and small,
    /// and the rest is rebuilt from the same store or archives with `all`.
    First,
}

/// A figure written as `<stem>.svg` and/or `<stem>.png`.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    pub env: String,
    pub pipeline: String,
    /// The file name without extension, relative to the report directory.
    pub stem: String,
    pub title: String,
}

/// Draws onto any plotters backend, so that one description gives both files.
trait Figure {
    fn title(&self) -> String;
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String>;
}

fn fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TrueType font shipped by the dejavu crate.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

fn e2s<E: std::fmt::Debug>(e: E) -> String {
    format!("{e:?}")
}

fn save(fig: &impl Figure, dir: &Path, stem: &str, formats: FigureFormats) -> Result<()> {
    fonts();
    let svg = dir.join(format!("{stem}.svg"));
    let fail = |path: &Path, e: String| Error::file(path, format!("cannot draw the figure: {e}"));
    if formats.svg() {
        let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
        root.fill(&WHITE)
            .map_err(e2s)
            .and_then(|_| fig.draw(&root))
            .and_then(|_| root.present().map_err(e2s))
            .map_err(|e| fail(&svg, e))?;
    }
    if !formats.png() {
        return Ok(());
    }
    let png = dir.join(format!("{stem}.png"));
    let mut pixels = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, SIZE).into_drawing_area();
        root.fill(&WHITE)
            .map_err(e2s)
            .and_then(|_| fig.draw(&root))
            .and_then(|_| root.present().map_err(e2s))
            .map_err(|e| fail(&png, e))?;
    }
    let file = std::fs::File::create(&png).map_err(|e| Error::io(&png, e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), SIZE.0, SIZE.1);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.write_header().and_then(|mut w| w.write_image_data(&pixels)).map_err(|e| Error::file(&png, format!("cannot write PNG: {e}")))
}

/// Colours by method, the same in every figure.
fn method_colour(m: Method) -> RGBColor {
    let [r, g, b] = m.colour();
    RGBColor(r, g, b)
}
const SERIES: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];
const DEMOS: RGBColor = RGBColor(0, 0, 0);

/// The value range of `xs`, padded by 5 % (and never empty).
fn range(xs: impl IntoIterator<Item = f64>) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in xs.into_iter().filter(|x| x.is_finite()) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if !lo.is_finite() {
        return 0.0..1.0;
    }
    let pad = ((hi - lo) * 0.05).max(1e-6);
    (lo - pad)..(hi + pad)
}

/// The legend box, in `corner`.
fn legend<'a, DB: DrawingBackend + 'a, X: Ranged, Y: Ranged>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    corner: SeriesLabelPosition,
) -> std::result::Result<(), String> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 14))
        .position(corner)
        .draw()
        .map_err(e2s)
}

/// What the figures of one (env, pipeline) are drawn from.
#[derive(Default)]
struct Group {
    demos: Option<(f64, f64)>,
    /// Rollout-set key -> (node name, degradation), in first-seen order by key.
    sets: BTreeMap<String, (String, Vec<DegradationLevel>)>,
    /// Method -> reward key (iteration 1's for iD-REX; the first seen).
    rewards: BTreeMap<Method, String>,
    /// Method -> unseen evaluation (true, predicted) pairs.
    unseen: BTreeMap<Method, Vec<(f64, f64)>>,
    runs: Runs,
    /// The replicate of the table's evaluations.
    replicate: usize,
}

fn typed<'a>(store: &'a Artifacts, key: &str) -> Option<(&'a Manifest, &'a Typed)> {
    let m = store.get(key)?;
    Some((m, store.typed(m)?))
}

fn degradation_of(m: &Metrics) -> Option<Vec<DegradationLevel>> {
    match m {
        Metrics::NoiseRollouts(x) => Some(x.degradation.clone()),
        Metrics::InterpolationRollouts(x) | Metrics::ActionNoiseRollouts(x) => Some(x.degradation.clone()),
        Metrics::MultiBcRollouts(x) => Some(x.degradation.clone()),
        _ => None,
    }
}

/// The uniform-random return a multi-BC stage (by node name) measured.
fn store_random(store: &Artifacts, node: &str) -> Option<f64> {
    store.iter().filter(|m| m.node == node).find_map(|m| match store.typed(m) {
        Some(Typed { metrics: Metrics::MultiBcRollouts(x), .. }) => Some(x.random_return),
        _ => None,
    })
}

/// Writes every figure into `dir`; returns what it wrote, for the markdown to link.
pub fn write(
    store: &Artifacts,
    protocols: &[ProtocolRow],
    aggregate: &[AggregateRow],
    clone_rows: &[super::clones::CloneRow],
    dir: &Path,
    (formats, replicates): (FigureFormats, ReplicateFigures),
) -> Result<Vec<Written>> {
    let mut groups = groups(store);
    if replicates == ReplicateFigures::First {
        groups.retain(|_, g| g.replicate == 0);
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut written = Vec::new();
    let groups_demos: BTreeMap<(String, String), f64> = groups.iter().filter_map(|(k, g)| g.demos.map(|d| (k.clone(), d.0))).collect();
    for ((env, pipeline), g) in groups {
        table_figures(store, (&env, &pipeline), g, (protocols, clone_rows), (dir, formats), &mut written)?;
    }
    study_figures(protocols, aggregate, &groups_demos, (dir, formats), &mut written)?;
    Ok(written)
}

/// Per (environment, table), what its figures draw, read from the evaluations and the
/// rewards and ranked sets behind them.
fn groups(store: &Artifacts) -> BTreeMap<(String, String), Group> {
    let mut groups: BTreeMap<(String, String), Group> = BTreeMap::new();
    for (m, p, x) in store.evaluations() {
        let g = groups.entry((p.env.name().to_string(), p.table())).or_default();
        g.replicate = p.replicate;
        if g.demos.is_none()
            && let Some((_, Typed { metrics: Metrics::Demos(d) | Metrics::DemosImport(d), .. })) =
                super::input_key(m, Role::Demos).and_then(|k| typed(store, k))
        {
            g.demos = Some((d.stats.mean, d.stats.std));
        }
        if !x.checkpoints.is_empty() && p.iteration <= 2 {
            let points = x
                .checkpoints
                .iter()
                .map(|c| (c.step as f64, c.returns.iter().sum::<f64>() / c.returns.len().max(1) as f64, c.learned.map(|l| l.mean)))
                .collect();
            g.runs.push((p.method, p.run, points));
        }
        let Some(reward) = super::input_key(m, Role::Reward) else { continue };
        if let Some(acc) = &x.reward {
            g.unseen.entry(p.method).or_default().extend(x.summary.returns.iter().copied().zip(acc.predicted_returns.iter().copied()));
        }
        if g.rewards.contains_key(&p.method) {
            continue;
        }
        g.rewards.insert(p.method, reward.clone());
        if let Some(rm) = store.get(reward) {
            for (key, sm) in store.inputs_in(rm, Series::Set) {
                if !g.sets.contains_key(key)
                    && let Some(st) = store.typed(sm)
                    && let Some(levels) = degradation_of(&st.metrics)
                {
                    g.sets.insert(key.clone(), (sm.node.clone(), levels));
                }
            }
        }
    }
    groups
}

/// The figures of one (environment, table): degradation, each reward's scatter, PPO's
/// curves, the clones and the final bars.
fn table_figures(
    store: &Artifacts,
    (env, pipeline): (&str, &str),
    mut g: Group,
    (protocols, clone_rows): (&[ProtocolRow], &[super::clones::CloneRow]),
    (dir, formats): (&Path, FigureFormats),
    written: &mut Vec<Written>,
) -> Result<()> {
    let slug = format!("{}-{}", env.to_lowercase(), pipeline).replace(['/', ' ', '[', ']', ',', '='], "_");
    let mut emit = |fig: &dyn Fn(&Path, &str) -> Result<String>, name: &str| -> Result<()> {
        let stem = format!("{slug}-{name}");
        let title = fig(dir, &stem)?;
        written.push(Written { env: env.to_string(), pipeline: pipeline.to_string(), stem, title });
        Ok(())
    };
    let curves: Vec<Curve> = g.sets.values().map(|(node, levels)| Curve { source: node.clone(), levels: levels.clone() }).collect();
    if !curves.is_empty() {
        let fig = Degradation { env: env.to_string(), pipeline: pipeline.to_string(), curves, demos: g.demos };
        emit(&|d, s| save(&fig, d, s, formats).map(|_| fig.title()), "degradation")?;
    }
    for (method, reward) in &g.rewards {
        let Some((_, Typed { metrics: Metrics::Trex(t), .. })) = typed(store, reward) else { continue };
        let pairs = |truth: &[f64], pred: &[f64]| truth.iter().copied().zip(pred.iter().copied()).collect::<Vec<_>>();
        let fig = RewardScatter {
            env: env.to_string(),
            pipeline: pipeline.to_string(),
            method: *method,
            sets: vec![
                ("training set", pairs(&t.train_set.scored.truth, &t.train_set.scored.predicted)),
                ("demonstrations", pairs(&t.demos.truth, &t.demos.predicted)),
                ("unseen evaluation rollouts", g.unseen.get(method).cloned().unwrap_or_default()),
            ],
        };
        emit(&|d, s| save(&fig, d, s, formats).map(|_| fig.title()), &format!("reward-{}", method.name()))?;
    }
    if !g.runs.is_empty() {
        g.runs.sort_by_key(|r| (r.0, r.1));
        let fig = PpoCurves { env: env.to_string(), pipeline: pipeline.to_string(), runs: std::mem::take(&mut g.runs), demos: g.demos };
        emit(&|d, s| save(&fig, d, s, formats).map(|_| fig.title()), "ppo")?;
    }
    let rows: Vec<_> = clone_rows.iter().filter(|r| r.env == env && r.pipeline == pipeline).cloned().collect();
    if !rows.is_empty() {
        let random = rows.iter().find_map(|r| store_random(store, &r.node));
        let fig = clones::CloneScatter { env: env.to_string(), pipeline: pipeline.to_string(), rows, random };
        emit(&|d, s| save(&fig, d, s, formats).map(|_| fig.title()), "clones")?;
    }
    let rows: Vec<ProtocolRow> = protocols.iter().filter(|r| r.env == env && r.pipeline == pipeline).cloned().collect();
    if !rows.is_empty() {
        let fig = FinalBars { env: env.to_string(), pipeline: pipeline.to_string(), rows, demos: g.demos.map(|d| d.0) };
        emit(&|d, s| save(&fig, d, s, formats).map(|_| fig.title()), "final")?;
    }
    Ok(())
}

/// Per (environment, study) with several replicates: the intervals and the profile.
fn study_figures(
    protocols: &[ProtocolRow],
    aggregate: &[AggregateRow],
    groups_demos: &BTreeMap<(String, String), f64>,
    (dir, formats): (&Path, FigureFormats),
    written: &mut Vec<Written>,
) -> Result<()> {
    let mut studies: Vec<(&str, &str)> = aggregate.iter().map(|a| (a.env.as_str(), a.study.as_str())).collect();
    studies.dedup();
    for (env, study) in studies {
        let slug = format!("{}-study-{}", env.to_lowercase(), study).replace(['/', ' ', '[', ']', ',', '='], "_");
        // The demonstrations of the study's first table (every table of a study has the same).
        let demos = protocols
            .iter()
            .find(|r| r.env == env && r.study == study)
            .and_then(|r| groups_demos.get(&(env.to_string(), r.pipeline.clone())).copied());
        let label = format!("study {study}");
        let rows: Vec<AggregateRow> = aggregate.iter().filter(|a| a.env == env && a.study == study).cloned().collect();
        let fig = studies::Intervals { env: env.into(), study: study.into(), rows, demos };
        save(&fig, dir, &format!("{slug}-intervals"), formats)?;
        written.push(Written { env: env.into(), pipeline: label.clone(), stem: format!("{slug}-intervals"), title: fig.title() });
        let fig = studies::Profile::of(env, study, protocols, demos);
        save(&fig, dir, &format!("{slug}-profile"), formats)?;
        written.push(Written { env: env.into(), pipeline: label, stem: format!("{slug}-profile"), title: fig.title() });
    }
    Ok(())
}

/// The markdown section linking every figure (the PNG with the SVG beside it, or the one
/// format written).
pub fn markdown(written: &[Written], dir_name: &str, formats: FigureFormats) -> String {
    let mut out = String::from("\n## Figures\n");
    let mut last: Option<(&str, &str)> = None;
    for w in written {
        if last != Some((&w.env, &w.pipeline)) {
            out.push_str(&format!("\n### {} {}\n", w.env, w.pipeline));
            last = Some((&w.env, &w.pipeline));
        }
        let png = PathBuf::from(dir_name).join(format!("{}.png", w.stem));
        let svg = PathBuf::from(dir_name).join(format!("{}.svg", w.stem));
        match formats {
            FigureFormats::Both => {
                out.push_str(&format!("\n{} ([SVG]({}))\n\n![{}]({})\n", w.title, svg.display(), w.title, png.display()))
            }
            FigureFormats::Svg => out.push_str(&format!("\n{}\n\n![{}]({})\n", w.title, w.title, svg.display())),
            FigureFormats::Png => out.push_str(&format!("\n{}\n\n![{}]({})\n", w.title, w.title, png.display())),
        }
    }
    out
}
