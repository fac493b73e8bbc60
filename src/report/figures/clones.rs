//! `clones`: each multi-BC clone's noise-free true return against its source's (the report's
//! Figure 9 as a scatter), with the line where a clone equals its source and the
//! uniform-random policy's return.
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{FONT, Figure, MINOR_GRID, e2s, legend, range};
use crate::report::clones::CloneRow;

pub struct CloneScatter {
    pub env: String,
    pub pipeline: String,
    pub rows: Vec<CloneRow>,
    /// The uniform-random policy's mean return, where measured.
    pub random: Option<f64>,
}

impl Figure for CloneScatter {
    fn title(&self) -> String {
        format!("{} {}: multi-BC clones against their sources (true return, noise-free)", self.env, self.pipeline)
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> std::result::Result<(), String> {
        let xs = || self.rows.iter().map(CloneRow::source_return).chain(self.random);
        let ys = || self.rows.iter().map(CloneRow::clone_return).chain(self.random);
        let all = range(xs().chain(ys()));
        let mut chart = ChartBuilder::on(root)
            .caption(self.title(), (FONT, 18))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(all.clone(), all.clone())
            .map_err(e2s)?;
        chart
            .configure_mesh()
            .max_light_lines(MINOR_GRID)
            .x_desc("source: true return of the episodes the clone learned from")
            .y_desc("clone: mean true return of its noise-free episodes")
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()
            .map_err(e2s)?;
        let grey = RGBColor(120, 120, 120);
        chart
            .draw_series(LineSeries::new([(all.start, all.start), (all.end, all.end)], grey.stroke_width(1)))
            .map_err(e2s)?
            .label("clone = source")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], grey));
        if let Some(r) = self.random {
            let black = RGBColor(0, 0, 0);
            chart
                .draw_series(DashedLineSeries::new([(all.start, r), (all.end, r)], 6, 4, black.stroke_width(1)))
                .map_err(e2s)?
                .label(format!("uniform-random policy ({r:.0})"))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], black));
        }
        for (kept, colour, name) in [(true, RGBColor(214, 39, 40), "kept by the filter"), (false, RGBColor(31, 119, 180), "rejected")] {
            let pts: Vec<(f64, f64)> =
                self.rows.iter().filter(|r| r.record.kept == kept).map(|r| (r.source_return(), r.clone_return())).collect();
            if pts.is_empty() {
                continue;
            }
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 6, colour.filled())))
                .map_err(e2s)?
                .label(format!("{name} ({} clones)", pts.len()))
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.filled()));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}
