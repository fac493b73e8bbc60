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
//! - `clones`: multi-BC's clones against their sources ([`clones`]);
//! - per (environment, study) with several replicates, `intervals` and `profile`
//!   ([`studies`]).
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

mod clones;
mod studies;

use super::Artifacts;
use super::studies::AggregateRow;
use super::{Protocol, ProtocolRow};
use crate::error::{Error, Result};
use crate::pipeline::Method;
use crate::pipeline::stage::{DegradationLevel, Metrics, Params, Typed};
use crate::stats::pearson;
use crate::store::Manifest;

const SIZE: (u32, u32) = (960, 640);
const FONT: &str = "sans-serif";

/// A figure written as `<stem>.svg` and `<stem>.png`.
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

fn save(fig: &impl Figure, dir: &Path, stem: &str) -> Result<()> {
    fonts();
    let svg = dir.join(format!("{stem}.svg"));
    let fail = |path: &Path, e: String| Error::file(path, format!("cannot draw the figure: {e}"));
    {
        let root = SVGBackend::new(&svg, SIZE).into_drawing_area();
        root.fill(&WHITE)
            .map_err(e2s)
            .and_then(|_| fig.draw(&root))
            .and_then(|_| root.present().map_err(e2s))
            .map_err(|e| fail(&svg, e))?;
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

/// One rollout set's degradation curve.
struct Curve {
    source: String,
    levels: Vec<DegradationLevel>,
}

struct Degradation {
    env: String,
    pipeline: String,
    curves: Vec<Curve>,
    demos: Option<(f64, f64)>,
}

impl Figure for Degradation {
    fn title(&self) -> String {
        format!("{} {}: return against noise, per ranked rollout set", self.env, self.pipeline)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let ys = self.curves.iter().flat_map(|c| c.levels.iter().flat_map(|l| [l.mean - l.std, l.mean + l.std]));
        let demo_ys = self.demos.into_iter().flat_map(|(m, s)| [m - s, m + s]);
        let x_max = self.curves.iter().flat_map(|c| c.levels.iter().map(|l| l.noise)).fold(1.0, f64::max);
        let mut chart = ChartBuilder::on(root)
            .caption(self.title(), (FONT, 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max, range(ys.chain(demo_ys)))
            .map_err(e2s)?;
        chart
            .configure_mesh()
            .x_desc("noise level (epsilon; 1 - alpha for interpolation)")
            .y_desc("true return")
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()
            .map_err(e2s)?;
        if let Some((m, s)) = self.demos {
            chart.draw_series([Rectangle::new([(0.0, m - s), (x_max, m + s)], DEMOS.mix(0.08).filled())]).map_err(e2s)?;
            chart
                .draw_series(LineSeries::new([(0.0, m), (x_max, m)], DEMOS.stroke_width(2)))
                .map_err(e2s)?
                .label(format!("demonstrations ({m:.1} ± {s:.1})"))
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], DEMOS.stroke_width(2)));
        }
        for (i, c) in self.curves.iter().enumerate() {
            let colour = SERIES[i % SERIES.len()];
            let band: Vec<(f64, f64)> = c
                .levels
                .iter()
                .map(|l| (l.noise, l.mean + l.std))
                .chain(c.levels.iter().rev().map(|l| (l.noise, l.mean - l.std)))
                .collect();
            chart.draw_series([Polygon::new(band, colour.mix(0.15).filled())]).map_err(e2s)?;
            chart
                .draw_series(LineSeries::new(c.levels.iter().map(|l| (l.noise, l.mean)), colour.stroke_width(2)).point_size(3))
                .map_err(e2s)?
                .label(format!("{} (mean ± std)", c.source))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }
}

/// Predicted against true return of one method's reward.
struct RewardScatter {
    env: String,
    pipeline: String,
    method: Method,
    /// (set name, (true, predicted) pairs)
    sets: Vec<(&'static str, Vec<(f64, f64)>)>,
}

impl Figure for RewardScatter {
    fn title(&self) -> String {
        format!("{} {}: {} learned reward, predicted against true return", self.env, self.pipeline, self.method.label())
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let all = || self.sets.iter().flat_map(|(_, v)| v.iter().copied());
        let mut chart = ChartBuilder::on(root)
            .caption(self.title(), (FONT, 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(range(all().map(|p| p.0)), range(all().map(|p| p.1)))
            .map_err(e2s)?;
        chart
            .configure_mesh()
            .x_desc("true return")
            .y_desc("predicted return (ensemble mean, summed over the episode)")
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()
            .map_err(e2s)?;
        let colours = [RGBColor(31, 119, 180), RGBColor(214, 39, 40), RGBColor(44, 160, 44)];
        for ((name, pts), colour) in self.sets.iter().zip(colours) {
            let (t, p): (Vec<f64>, Vec<f64>) = pts.iter().copied().unzip();
            let r = pearson(&t, &p);
            let label = if r.is_finite() {
                format!("{name} ({} episodes, Pearson {r:.2})", pts.len())
            } else {
                format!("{name} ({} episodes)", pts.len())
            };
            let size = if *name == "demonstrations" { 7 } else { 4 };
            chart
                .draw_series(pts.iter().map(|&(x, y)| Circle::new((x, y), size, colour.filled())))
                .map_err(e2s)?
                .label(label)
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}

/// Per method and run: (step, true mean, learned mean) of every checkpoint.
type Runs = Vec<(Method, usize, Vec<(f64, f64, Option<f64>)>)>;

struct PpoCurves {
    env: String,
    pipeline: String,
    runs: Runs,
    demos: Option<(f64, f64)>,
}

impl Figure for PpoCurves {
    fn title(&self) -> String {
        format!("{} {}: PPO checkpoints, true (top) and learned (bottom) return", self.env, self.pipeline)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let root = root.titled(&self.title(), (FONT, 20)).map_err(e2s)?;
        let (top, bottom) = root.split_vertically(SIZE.1 as f64 * 0.47);
        let x_max = self.runs.iter().flat_map(|(_, _, c)| c.iter().map(|p| p.0)).fold(1.0, f64::max);
        for (area, learned) in [(top, false), (bottom, true)] {
            let value = |p: &(f64, f64, Option<f64>)| if learned { p.2 } else { Some(p.1) };
            let ys = self.runs.iter().flat_map(|(_, _, c)| c.iter().filter_map(value));
            let demo_ys = if learned { None } else { self.demos.map(|d| d.0) };
            let mut chart = ChartBuilder::on(&area)
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(80)
                .build_cartesian_2d(0.0..x_max, range(ys.chain(demo_ys)))
                .map_err(e2s)?;
            chart
                .configure_mesh()
                .x_desc("PPO environment steps")
                .y_desc(if learned { "learned return (ensemble mean)" } else { "true return" })
                .label_style((FONT, 13))
                .axis_desc_style((FONT, 15))
                .x_label_formatter(&|x| format!("{:.0}k", x / 1000.0))
                .draw()
                .map_err(e2s)?;
            if let (false, Some((m, _))) = (learned, self.demos) {
                chart
                    .draw_series(LineSeries::new([(0.0, m), (x_max, m)], DEMOS.stroke_width(2)))
                    .map_err(e2s)?
                    .label(format!("demonstrations ({m:.1})"))
                    .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], DEMOS.stroke_width(2)));
            }
            let mut labelled = std::collections::BTreeSet::new();
            for (method, _run, points) in &self.runs {
                let colour = method_colour(*method);
                let series = chart
                    .draw_series(LineSeries::new(points.iter().filter_map(|p| value(p).map(|v| (p.0, v))), colour.stroke_width(2)))
                    .map_err(e2s)?;
                // One legend entry per method; the runs share its colour.
                if labelled.insert(*method) {
                    let n = self.runs.iter().filter(|r| r.0 == *method).count();
                    series
                        .label(format!("{} ({n} runs)", method.label()))
                        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
                }
            }
            legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        }
        Ok(())
    }
}

/// The final comparison: per method, one bar per protocol with its bootstrap interval.
struct FinalBars {
    env: String,
    pipeline: String,
    rows: Vec<ProtocolRow>,
    demos: Option<f64>,
}

impl Figure for FinalBars {
    fn title(&self) -> String {
        format!("{} {}: true return per method and protocol (95 % bootstrap CI over runs)", self.env, self.pipeline)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let methods: Vec<Method> = Method::ALL.into_iter().filter(|m| self.rows.iter().any(|r| r.method == m.name())).collect();
        let ys = self.rows.iter().flat_map(|r| [r.ci.0, r.ci.1, r.stats.mean, 0.0]).chain(self.demos);
        let n = methods.len() as f64;
        let mut chart = ChartBuilder::on(root)
            .caption(self.title(), (FONT, 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5..(n - 0.5), range(ys))
            .map_err(e2s)?;
        let labels: Vec<&'static str> = methods.iter().map(|m| m.label()).collect();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(methods.len())
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 {
                    labels.get(i as usize).map_or(String::new(), |s| s.to_string())
                } else {
                    String::new()
                }
            })
            .x_desc("method")
            .y_desc("true return (mean over runs x episodes)")
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()
            .map_err(e2s)?;
        let width = 0.26;
        let protocol_colours = [RGBColor(31, 119, 180), RGBColor(255, 127, 14), RGBColor(44, 160, 44)];
        for (k, (protocol, colour)) in Protocol::ALL.into_iter().zip(protocol_colours).enumerate() {
            let offset = (k as f64 - 1.0) * width;
            let bars: Vec<(f64, &ProtocolRow)> = methods
                .iter()
                .enumerate()
                .filter_map(|(i, m)| {
                    self.rows.iter().find(|r| r.method == m.name() && r.protocol == protocol).map(|r| (i as f64 + offset, r))
                })
                .collect();
            chart
                .draw_series(
                    bars.iter().map(|&(x, r)| {
                        Rectangle::new([(x - width / 2.0 * 0.9, 0.0), (x + width / 2.0 * 0.9, r.stats.mean)], colour.filled())
                    }),
                )
                .map_err(e2s)?
                .label(protocol.name())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], colour.filled()));
            chart
                .draw_series(bars.iter().map(|&(x, r)| ErrorBar::new_vertical(x, r.ci.0, r.stats.mean, r.ci.1, BLACK.stroke_width(1), 8)))
                .map_err(e2s)?;
        }
        if let Some(d) = self.demos {
            chart
                .draw_series(LineSeries::new([(-0.5, d), (n - 0.5, d)], DEMOS.stroke_width(2)))
                .map_err(e2s)?
                .label(format!("demonstrations ({d:.1})"))
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], DEMOS.stroke_width(2)));
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }
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
}

fn typed<'a>(store: &'a Artifacts, key: &str) -> Option<(&'a Manifest, Typed)> {
    let m = store.get(key)?;
    Some((m, Typed::of(m).ok()?))
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
    store.iter().filter(|m| m.node == node).find_map(|m| match Typed::of(m) {
        Ok(Typed { metrics: Metrics::MultiBcRollouts(x), .. }) => Some(x.random_return),
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
) -> Result<Vec<Written>> {
    let mut groups: BTreeMap<(String, String), Group> = BTreeMap::new();
    for m in store.iter() {
        if m.kind != crate::pipeline::stage::StageKind::Eval.name() {
            continue;
        }
        let Ok(Typed { params: Params::Eval(p), metrics: Metrics::Eval(x) }) = Typed::of(&m) else { continue };
        let g = groups.entry((p.env.name().to_string(), p.table())).or_default();
        if g.demos.is_none()
            && let Some((_, Typed { metrics: Metrics::Demos(d) | Metrics::DemosImport(d), .. })) =
                m.inputs.get("demos").and_then(|k| typed(store, k))
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
        let Some(reward) = m.inputs.get("reward") else { continue };
        if let Some(acc) = &x.reward {
            g.unseen.entry(p.method).or_default().extend(x.summary.returns.iter().copied().zip(acc.predicted_returns.iter().copied()));
        }
        if g.rewards.contains_key(&p.method) {
            continue;
        }
        g.rewards.insert(p.method, reward.clone());
        if let Some((rm, _)) = typed(store, reward) {
            for (role, key) in &rm.inputs {
                if role.starts_with("set")
                    && !g.sets.contains_key(key)
                    && let Some((sm, st)) = typed(store, key)
                    && let Some(levels) = degradation_of(&st.metrics)
                {
                    g.sets.insert(key.clone(), (sm.node.clone(), levels));
                }
            }
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut written = Vec::new();
    let groups_demos: BTreeMap<(String, String), f64> = groups.iter().filter_map(|(k, g)| g.demos.map(|d| (k.clone(), d.0))).collect();
    for ((env, pipeline), mut g) in groups {
        let slug = format!("{}-{}", env.to_lowercase(), pipeline).replace(['/', ' '], "_");
        let mut emit = |fig: &dyn Fn(&Path, &str) -> Result<String>, name: &str| -> Result<()> {
            let stem = format!("{slug}-{name}");
            let title = fig(dir, &stem)?;
            written.push(Written { env: env.clone(), pipeline: pipeline.clone(), stem, title });
            Ok(())
        };
        let curves: Vec<Curve> = g.sets.values().map(|(node, levels)| Curve { source: node.clone(), levels: levels.clone() }).collect();
        if !curves.is_empty() {
            let fig = Degradation { env: env.clone(), pipeline: pipeline.clone(), curves, demos: g.demos };
            emit(&|d, s| save(&fig, d, s).map(|_| fig.title()), "degradation")?;
        }
        for (method, reward) in &g.rewards {
            let Some((_, Typed { metrics: Metrics::Trex(t), .. })) = typed(store, reward) else { continue };
            let pairs = |truth: &[f64], pred: &[f64]| truth.iter().copied().zip(pred.iter().copied()).collect::<Vec<_>>();
            let fig = RewardScatter {
                env: env.clone(),
                pipeline: pipeline.clone(),
                method: *method,
                sets: vec![
                    ("training set", pairs(&t.train_set.scored.truth, &t.train_set.scored.predicted)),
                    ("demonstrations", pairs(&t.demos.truth, &t.demos.predicted)),
                    ("unseen evaluation rollouts", g.unseen.get(method).cloned().unwrap_or_default()),
                ],
            };
            emit(&|d, s| save(&fig, d, s).map(|_| fig.title()), &format!("reward-{}", method.name()))?;
        }
        if !g.runs.is_empty() {
            g.runs.sort_by_key(|r| (r.0, r.1));
            let fig = PpoCurves { env: env.clone(), pipeline: pipeline.clone(), runs: std::mem::take(&mut g.runs), demos: g.demos };
            emit(&|d, s| save(&fig, d, s).map(|_| fig.title()), "ppo")?;
        }
        let rows: Vec<_> = clone_rows.iter().filter(|r| r.env == env && r.pipeline == pipeline).cloned().collect();
        if !rows.is_empty() {
            let random = rows.iter().find_map(|r| store_random(store, &r.node));
            let fig = clones::CloneScatter { env: env.clone(), pipeline: pipeline.clone(), rows, random };
            emit(&|d, s| save(&fig, d, s).map(|_| fig.title()), "clones")?;
        }
        let rows: Vec<ProtocolRow> = protocols.iter().filter(|r| r.env == env && r.pipeline == pipeline).cloned().collect();
        if !rows.is_empty() {
            let fig = FinalBars { env: env.clone(), pipeline: pipeline.clone(), rows, demos: g.demos.map(|d| d.0) };
            emit(&|d, s| save(&fig, d, s).map(|_| fig.title()), "final")?;
        }
    }
    let mut studies: Vec<(&str, &str)> = aggregate.iter().map(|a| (a.env.as_str(), a.study.as_str())).collect();
    studies.dedup();
    for (env, study) in studies {
        let slug = format!("{}-study-{}", env.to_lowercase(), study).replace(['/', ' '], "_");
        // The demonstrations of the study's first table (every table of a study has the same).
        let demos = protocols
            .iter()
            .find(|r| r.env == env && r.study == study)
            .and_then(|r| groups_demos.get(&(env.to_string(), r.pipeline.clone())).copied());
        let label = format!("study {study}");
        let rows: Vec<AggregateRow> = aggregate.iter().filter(|a| a.env == env && a.study == study).cloned().collect();
        let fig = studies::Intervals { env: env.into(), study: study.into(), rows, demos };
        save(&fig, dir, &format!("{slug}-intervals"))?;
        written.push(Written { env: env.into(), pipeline: label.clone(), stem: format!("{slug}-intervals"), title: fig.title() });
        let fig = studies::Profile::of(env, study, protocols, demos);
        save(&fig, dir, &format!("{slug}-profile"))?;
        written.push(Written { env: env.into(), pipeline: label, stem: format!("{slug}-profile"), title: fig.title() });
    }
    Ok(written)
}

/// The markdown section linking every figure (PNG, with the SVG beside it).
pub fn markdown(written: &[Written], dir_name: &str) -> String {
    let mut out = String::from("\n## Figures\n");
    let mut last: Option<(&str, &str)> = None;
    for w in written {
        if last != Some((&w.env, &w.pipeline)) {
            out.push_str(&format!("\n### {} {}\n", w.env, w.pipeline));
            last = Some((&w.env, &w.pipeline));
        }
        let png = PathBuf::from(dir_name).join(format!("{}.png", w.stem));
        let svg = PathBuf::from(dir_name).join(format!("{}.svg", w.stem));
        out.push_str(&format!("\n{} ([SVG]({}))\n\n![{}]({})\n", w.title, svg.display(), w.title, png.display()));
    }
    out
}
