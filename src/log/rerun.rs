//! Plots as Rerun recordings (`.rrd`), opened with `rerun FILE.rrd`. The stream is recorded
//! in memory and written by us: Rerun's own file sink stops on an I/O error (a full disk)
//! and its flush then waits forever. Entity paths are fixed: `degradation/<source>/…`,
//! `reward/<set>/…`, `ppo/<run>/…`, `trex/model<m>/…`.
use std::path::Path;

use crate::error::{Error, Result};

pub struct Recording {
    rec: rerun::RecordingStream,
    storage: rerun::sink::MemorySinkStorage,
}

fn err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::file(path, format!("cannot write Rerun recording: {e}"))
}

impl Recording {
    pub fn create(path: &Path, name: &str) -> Result<Self> {
        let (rec, storage) =
            rerun::RecordingStreamBuilder::new("idrex").recording_name(name.to_string()).memory().map_err(|e| err(path, e))?;
        Ok(Recording { rec, storage })
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

    /// Encodes the recording and writes it to `path` (fsynced).
    pub fn finish(self, path: &Path) -> Result<()> {
        let bytes = self.storage.drain_as_bytes().map_err(|e| err(path, e))?;
        std::fs::write(path, bytes).map_err(|e| Error::io(path, e))?;
        std::fs::File::open(path).and_then(|f| f.sync_all()).map_err(|e| Error::io(path, e))
    }
}
