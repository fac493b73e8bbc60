//! Plots as Rerun recordings (`.rrd`), opened with `rerun FILE.rrd`, laid out by a blueprint
//! sent with the recording: one titled panel per figure, nothing automatic.
//!
//! Every plot is a time series view over one shared sequence timeline, [`X`]: a view's own
//! x quantity (noise level in ‰, PPO step, true return, T-REX iteration) is logged on it, and
//! the view's title says which. Rerun plots every view against the one timeline selected in
//! the time panel, so separate timelines per quantity would leave all but one view empty.
//! Each row carries only that timeline (the time is reset before every row, and Rerun's
//! automatic `log_time` and `log_tick` are off), so no row inherits another plot's x.
//!
//! The stream is recorded in memory and written by us: Rerun's own file sink stops on an I/O
//! error (a full disk) and its flush then waits forever.
use std::path::Path;

use rerun::blueprint::components::PanelState;
use rerun::blueprint::{
    Blueprint, BlueprintActivation, BlueprintPanel, ContainerLike, Grid, SelectionPanel, TextDocumentView, TimePanel, TimeSeriesView,
};

use crate::error::{Error, Result};

/// The one plot timeline.
pub const X: &str = "x";

pub struct Recording {
    rec: rerun::RecordingStream,
    storage: rerun::sink::MemorySinkStorage,
}

fn err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::file(path, format!("cannot write Rerun recording: {e}"))
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    Line,
    ThinLine,
    Points,
}

/// One panel of the layout.
pub enum Panel {
    /// A plot of the entities matching `contents` (Rerun query expressions), titled.
    Plot { title: String, contents: Vec<String> },
    /// A markdown document logged at `entity`.
    Text { title: String, entity: String },
}

impl Recording {
    pub fn create(path: &Path, name: &str) -> Result<Self> {
        let (rec, storage) =
            rerun::RecordingStreamBuilder::new("idrex").recording_name(name.to_string()).memory().map_err(|e| err(path, e))?;
        rec.set_log_time_enabled(false);
        rec.set_log_tick_enabled(false);
        Ok(Recording { rec, storage })
    }

    /// Names a series and how it is drawn (its legend entry).
    pub fn series(&self, entity: &str, name: &str, style: Style) {
        let _ = match style {
            Style::Line => self.rec.log_static(entity, &rerun::SeriesLines::new().with_names([name]).with_widths([2.0])),
            Style::ThinLine => self.rec.log_static(entity, &rerun::SeriesLines::new().with_names([name]).with_widths([0.75])),
            Style::Points => self.rec.log_static(
                entity,
                &rerun::SeriesPoints::new()
                    .with_names([name])
                    .with_markers([rerun::components::MarkerShape::Circle])
                    .with_marker_sizes([3.0]),
            ),
        };
    }

    /// One point of a series: `value` at `x` on the plot timeline, and no other time.
    pub fn scalar(&self, entity: &str, x: i64, value: f64) {
        self.rec.reset_time();
        self.rec.set_time_sequence(X, x);
        let _ = self.rec.log(entity, &rerun::Scalars::single(value));
    }

    /// A labelled marker on a plot (a chosen checkpoint on a learning curve).
    pub fn marker(&self, entity: &str, x: i64, value: f64, label: &str) {
        let style =
            rerun::SeriesPoints::new().with_names([label]).with_markers([rerun::components::MarkerShape::Diamond]).with_marker_sizes([8.0]);
        let _ = self.rec.log_static(entity, &style);
        self.scalar(entity, x, value);
    }

    /// A markdown document.
    pub fn markdown(&self, entity: &str, text: &str) {
        let doc = rerun::TextDocument::new(text).with_media_type(rerun::MediaType::markdown());
        let _ = self.rec.log_static(entity, &doc);
    }

    /// Sends the layout: the panels in a grid, automatic views off, the plot timeline
    /// selected, the side and time panels collapsed so that the plots have the window.
    pub fn layout(&self, path: &Path, panels: Vec<Panel>) -> Result<()> {
        let views: Vec<ContainerLike> = panels
            .into_iter()
            .map(|p| match p {
                Panel::Plot { title, contents } => TimeSeriesView::new(title).with_contents(contents).into(),
                Panel::Text { title, entity } => TextDocumentView::new(title).with_origin(entity.as_str()).into(),
            })
            .collect();
        Blueprint::new(Grid::new(views))
            .with_auto_views(false)
            .with_auto_layout(false)
            .with_time_panel(TimePanel::new().with_timeline(X).with_state(PanelState::Collapsed))
            .with_blueprint_panel(BlueprintPanel::new().with_state(PanelState::Collapsed))
            .with_selection_panel(SelectionPanel::new().with_state(PanelState::Collapsed))
            .send(&self.rec, BlueprintActivation::default())
            .map_err(|e| err(path, e))
    }

    /// Encodes the recording and writes it to `path` (fsynced).
    pub fn finish(self, path: &Path) -> Result<()> {
        let bytes = self.storage.drain_as_bytes().map_err(|e| err(path, e))?;
        std::fs::write(path, bytes).map_err(|e| Error::io(path, e))?;
        std::fs::File::open(path).and_then(|f| f.sync_all()).map_err(|e| Error::io(path, e))
    }
}
