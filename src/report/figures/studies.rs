//! A replicated study's figures, per environment: the interval plot (every method's mean and
//! interquartile mean over replicates, with their 95 % intervals, under each protocol) and
//! the performance profile (the fraction of runs whose return is above each threshold), as
//! rliable draws them.
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{DEMOS, FONT, Figure, MINOR_GRID, e2s, legend, method_colour, range};
use crate::pipeline::Method;
use crate::report::studies::AggregateRow;
use crate::report::{Protocol, ProtocolRow};

/// Methods in the paper's order, then any others (iD-REX's later iterations) by name.
fn methods_of(names: impl Iterator<Item = String>) -> Vec<String> {
    let mut v: Vec<String> = names.collect();
    v.sort_by_key(|n| (Method::ALL.iter().position(|m| m.name() == n).unwrap_or(usize::MAX), n.clone()));
    v.dedup();
    v
}

fn colour(name: &str) -> RGBColor {
    Method::ALL.into_iter().find(|m| m.name() == name).map_or(RGBColor(0, 0, 0), method_colour)
}

pub struct Intervals {
    pub env: String,
    pub study: String,
    pub rows: Vec<AggregateRow>,
    pub demos: Option<f64>,
}

impl Figure for Intervals {
    fn title(&self) -> String {
        let n = self.rows.iter().map(|r| r.replicates).max().unwrap_or(0);
        format!("{} {}: mean (o) and IQM (^) over {n} replicates, 95 % CI (replicates, then runs)", self.env, self.study)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let (top, rest) = root.split_vertically(36);
        top.draw(&Text::new(self.title(), (10, 10), (FONT, 17))).map_err(e2s)?;
        let methods = methods_of(self.rows.iter().map(|r| r.method.clone()));
        let ys = range(self.rows.iter().flat_map(|r| [r.mean_ci.0, r.mean_ci.1, r.iqm_ci.0, r.iqm_ci.1]).chain(self.demos));
        let n = methods.len() as f64;
        for (panel, protocol) in rest.split_evenly((1, 3)).iter().zip(Protocol::ALL) {
            let mut chart = ChartBuilder::on(panel)
                .caption(protocol.name(), (FONT, 15))
                .margin(8)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(-0.5..(n - 0.5), ys.clone())
                .map_err(e2s)?;
            chart
                .configure_mesh()
                .max_light_lines(MINOR_GRID)
                .disable_x_mesh()
                .x_labels(0)
                .y_desc("true return")
                .label_style((FONT, 12))
                .axis_desc_style((FONT, 14))
                .draw()
                .map_err(e2s)?;
            for (i, m) in methods.iter().enumerate() {
                let Some(r) = self.rows.iter().find(|r| &r.method == m && r.protocol == protocol) else { continue };
                let c = colour(m);
                let (xm, xi) = (i as f64 - 0.15, i as f64 + 0.15);
                chart.draw_series([ErrorBar::new_vertical(xm, r.mean_ci.0, r.mean, r.mean_ci.1, c.stroke_width(2), 10)]).map_err(e2s)?;
                chart.draw_series([Circle::new((xm, r.mean), 5, c.filled())]).map_err(e2s)?;
                chart.draw_series([ErrorBar::new_vertical(xi, r.iqm_ci.0, r.iqm, r.iqm_ci.1, c.stroke_width(2), 10)]).map_err(e2s)?;
                let series = chart.draw_series([TriangleMarker::new((xi, r.iqm), 7, c.filled())]).map_err(e2s)?;
                if protocol == Protocol::Final {
                    series.label(m.clone()).legend(move |(x, y)| Circle::new((x + 6, y), 5, c.filled()));
                }
            }
            if let Some(d) = self.demos {
                let line = chart.draw_series(LineSeries::new([(-0.5, d), (n - 0.5, d)], DEMOS.stroke_width(1))).map_err(e2s)?;
                if protocol == Protocol::Final {
                    line.label(format!("demonstrations ({d:.1})"))
                        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], DEMOS.stroke_width(1)));
                }
            }
            if protocol == Protocol::Final {
                legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
            }
        }
        Ok(())
    }
}

pub struct Profile {
    pub env: String,
    pub study: String,
    /// The final policies' per-run mean returns of every replicate, by method.
    pub runs: Vec<(String, Vec<f64>)>,
    pub demos: Option<f64>,
}

impl Profile {
    pub fn of(env: &str, study: &str, rows: &[ProtocolRow], demos: Option<f64>) -> Profile {
        let mine: Vec<&ProtocolRow> = rows.iter().filter(|r| r.env == env && r.study == study && r.protocol == Protocol::Final).collect();
        let runs = methods_of(mine.iter().map(|r| r.method.clone()))
            .into_iter()
            .map(|m| {
                let v = mine.iter().filter(|r| r.method == m).flat_map(|r| r.run_means.iter().copied()).collect();
                (m, v)
            })
            .collect();
        Profile { env: env.into(), study: study.into(), runs, demos }
    }
}

impl Figure for Profile {
    fn title(&self) -> String {
        format!("{} {}: performance profile of the final policies (fraction of runs above each return)", self.env, self.study)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let xs = range(self.runs.iter().flat_map(|(_, v)| v.iter().copied()).chain(self.demos));
        let mut chart = ChartBuilder::on(root)
            .caption(self.title(), (FONT, 17))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(xs.clone(), 0.0..1.02)
            .map_err(e2s)?;
        chart
            .configure_mesh()
            .max_light_lines(MINOR_GRID)
            .x_desc("return threshold (run mean of the final policy)")
            .y_desc("fraction of runs above it")
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 15))
            .draw()
            .map_err(e2s)?;
        let steps = 200;
        for (m, v) in &self.runs {
            let c = colour(m);
            let points = (0..=steps).map(|k| {
                let t = xs.start + (xs.end - xs.start) * k as f64 / steps as f64;
                (t, v.iter().filter(|&&x| x > t).count() as f64 / v.len().max(1) as f64)
            });
            chart
                .draw_series(LineSeries::new(points, c.stroke_width(2)))
                .map_err(e2s)?
                .label(format!("{m} ({} runs)", v.len()))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        }
        if let Some(d) = self.demos {
            chart
                .draw_series(LineSeries::new([(d, 0.0), (d, 1.02)], DEMOS.stroke_width(1)))
                .map_err(e2s)?
                .label(format!("demonstrations ({d:.1})"))
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], DEMOS.stroke_width(1)));
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight)
    }
}
