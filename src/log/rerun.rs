//! Plots as Rerun recordings (`.rrd`, written with `RecordingStreamBuilder::save`), opened
//! with `rerun FILE.rrd`. Entity paths are fixed: `degradation/<source>/…`,
//! `reward/<set>/…`, `ppo/<run>/…`, `trex/model<m>/…`.
use std::path::Path;

use crate::error::{Error, Result};

pub struct Recording {
    rec: rerun::RecordingStream,
}

fn err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::file(path, format!("cannot write Rerun recording: {e}"))
}

impl Recording {
    pub fn create(path: &Path, name: &str) -> Result<Self> {
        let rec = rerun::RecordingStreamBuilder::new("idrex").recording_name(name.to_string()).save(path).map_err(|e| err(path, e))?;
        Ok(Recording { rec })
    }

    /// One point of a time series: `value` at `x` on `timeline`.
    pub fn scalar(&self, entity: &str, timeline: &'static str, x: i64, value: f64) {
        self.rec.set_time_sequence(timeline, x);
        let _ = self.rec.log(entity, &rerun::Scalars::single(value));
    }

    /// A marked point on a time series plot: `value` at `x` on `timeline`, drawn as a
    /// labelled marker (a chosen checkpoint on a learning curve).
    pub fn marker(&self, entity: &str, timeline: &'static str, x: i64, value: f64, label: &str) {
        let style =
            rerun::SeriesPoints::new().with_names([label]).with_markers([rerun::components::MarkerShape::Diamond]).with_marker_sizes([8.0]);
        let _ = self.rec.log_static(entity, &style);
        self.scalar(entity, timeline, x, value);
    }

    /// A scatter plot (static: it has no time axis).
    pub fn points(&self, entity: &str, xy: &[(f32, f32)], radius: f32) {
        let pts = rerun::Points2D::new(xy.iter().copied()).with_radii([radius]);
        let _ = self.rec.log_static(entity, &pts);
    }

    /// A line through `xy` (static).
    pub fn line(&self, entity: &str, xy: &[(f32, f32)]) {
        let strip = rerun::LineStrips2D::new([xy.iter().map(|&(x, y)| [x, y]).collect::<Vec<_>>()]);
        let _ = self.rec.log_static(entity, &strip);
    }

    pub fn text(&self, entity: &str, text: &str) {
        let _ = self.rec.log_static(entity, &rerun::TextDocument::new(text));
    }

    /// Waits until everything is written. Rerun's file sink stops writing after an I/O error
    /// (a full disk) and a blocking flush would then wait forever; a recording takes well
    /// under a second to flush, so 30 s without progress is an error.
    pub fn finish(self, path: &Path) -> Result<()> {
        self.rec.flush_with_timeout(std::time::Duration::from_secs(30)).map_err(|e| err(path, e))
    }
}
