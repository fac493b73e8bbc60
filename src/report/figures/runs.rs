//! The figures of one (environment, pipeline): degradation, reward scatter, PPO curves and
//! the final bars.
use plotters::coord::Shift;
use plotters::prelude::*;

use super::*;

/// One rollout set's degradation curve.
pub(super) struct Curve {
    pub(super) source: String,
    pub(super) levels: Vec<DegradationLevel>,
}

pub(super) struct Degradation {
    pub(super) env: String,
    pub(super) pipeline: String,
    pub(super) curves: Vec<Curve>,
    pub(super) demos: Option<(f64, f64)>,
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
            .max_light_lines(MINOR_GRID)
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
pub(super) struct RewardScatter {
    pub(super) env: String,
    pub(super) pipeline: String,
    pub(super) method: Method,
    /// (set name, (true, predicted) pairs)
    pub(super) sets: Vec<(&'static str, Vec<(f64, f64)>)>,
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
            .max_light_lines(MINOR_GRID)
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
pub(super) type Runs = Vec<(Method, usize, Vec<(f64, f64, Option<f64>)>)>;

pub(super) struct PpoCurves {
    pub(super) env: String,
    pub(super) pipeline: String,
    pub(super) runs: Runs,
    pub(super) demos: Option<(f64, f64)>,
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
                .max_light_lines(MINOR_GRID)
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
pub(super) struct FinalBars {
    pub(super) env: String,
    pub(super) pipeline: String,
    pub(super) rows: Vec<ProtocolRow>,
    pub(super) demos: Option<f64>,
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
            .max_light_lines(MINOR_GRID)
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
