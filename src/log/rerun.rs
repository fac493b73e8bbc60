//! Plots as Rerun recordings (`.rrd`), opened with `rerun FILE.rrd`, laid out by a blueprint
//! sent with the recording: one titled panel per figure, nothing automatic.
//!
//! Every plot is a time series view over one shared sequence timeline, [`X`]: a view's own
//! x quantity (noise level in ‰, PPO step, true return, T-REX iteration, replicate) is logged
//! on it, and the view's title says which. Rerun plots every view against the one timeline
//! selected in the time panel, so separate timelines per quantity would leave all but one
//! view empty. Each row carries only that timeline (the time is reset before every row, and
//! Rerun's automatic `log_time` and `log_tick` are off), so no row inherits another plot's x.
//!
//! So that every view shows all of its data on opening, whatever the sign and range of its x,
//! each view's blueprint sets (a) its visible time range on [`X`] to the whole timeline,
//! (b) its x axis independent of the other views' (by default Rerun links all time series
//! views' x axes to one global range) and (c) that axis's range to the view's own data:
//! by default it is a window around the time cursor, which opens at the smallest x of any
//! view (true returns around -1,000), so views whose x is environment steps showed nothing. The Rust
//! SDK's view builders cannot set view properties, so the blueprint is written here from
//! Rerun's blueprint archetypes, as the SDK's builder writes it.
//!
//! Legends: a view with at most [`LEGEND_MAX`] series shows its legend in the top-left
//! corner; with more (15 runs and up) the legend is hidden, the title says so, and the
//! series of one method share its colour (hovering a point names its series).
//!
//! The stream is recorded in memory and written by us: Rerun's own file sink stops on an I/O
//! error (a full disk) and its flush then waits forever.
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;

use rerun::blueprint::components::{
    ContainerKind, Corner2D, IncludedContent, LinkAxis, PanelState, QueryExpression, RootContainer, ViewClass,
};
use rerun::external::re_log_types::{BlueprintActivationCommand, RecordingId};
use rerun::external::re_sdk_types::blueprint::archetypes as bp;
use rerun::external::re_sdk_types::datatypes::{TimeInt, TimeRangeBoundary};

use crate::error::{Error, Result};

/// The one plot timeline.
pub const X: &str = "x";

/// The most series a view shows a legend for (more entries cover the data).
pub const LEGEND_MAX: usize = 4;

pub struct Recording {
    rec: rerun::RecordingStream,
    storage: rerun::sink::MemorySinkStorage,
    /// Series named per top-level entity (a view's root), for the legend policy.
    series: RefCell<BTreeMap<String, usize>>,
    /// The smallest and largest x logged per top-level entity: each view's x range.
    extent: RefCell<BTreeMap<String, (i64, i64)>>,
}

/// The top-level entity of a path: the root a view shows.
fn root_of(entity: &str) -> String {
    entity.trim_start_matches('/').split('/').next().unwrap_or_default().to_string()
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
    /// A plot of the entities under `/<root>/`, titled.
    Plot { title: String, root: String },
    /// A markdown document logged at `entity`.
    Text { title: String, entity: String },
}

impl Recording {
    pub fn create(path: &Path, name: &str) -> Result<Self> {
        let (rec, storage) =
            rerun::RecordingStreamBuilder::new("idrex").recording_name(name.to_string()).memory().map_err(|e| err(path, e))?;
        rec.set_log_time_enabled(false);
        rec.set_log_tick_enabled(false);
        Ok(Recording { rec, storage, series: RefCell::new(BTreeMap::new()), extent: RefCell::new(BTreeMap::new()) })
    }

    /// Names a series and how it is drawn (its legend entry).
    pub fn series(&self, entity: &str, name: &str, style: Style) {
        self.series_in(entity, name, style, None);
    }

    /// A series drawn in `colour` (RGB), as the other series of its group (a method's runs).
    pub fn series_coloured(&self, entity: &str, name: &str, style: Style, colour: [u8; 3]) {
        self.series_in(entity, name, style, Some(colour));
    }

    fn series_in(&self, entity: &str, name: &str, style: Style, colour: Option<[u8; 3]>) {
        *self.series.borrow_mut().entry(root_of(entity)).or_default() += 1;
        let colours = colour.map(|[r, g, b]| rerun::components::Color::from_rgb(r, g, b));
        let _ = match style {
            Style::Line | Style::ThinLine => {
                let width = if style == Style::Line { 2.0 } else { 0.75 };
                let mut lines = rerun::SeriesLines::new().with_names([name]).with_widths([width]);
                if let Some(c) = colours {
                    lines = lines.with_colors([c]);
                }
                self.rec.log_static(entity, &lines)
            }
            Style::Points => {
                let mut points = rerun::SeriesPoints::new()
                    .with_names([name])
                    .with_markers([rerun::components::MarkerShape::Circle])
                    .with_marker_sizes([3.0]);
                if let Some(c) = colours {
                    points = points.with_colors([c]);
                }
                self.rec.log_static(entity, &points)
            }
        };
    }

    /// One point of a series: `value` at `x` on the plot timeline, and no other time.
    pub fn scalar(&self, entity: &str, x: i64, value: f64) {
        {
            let mut extent = self.extent.borrow_mut();
            let e = extent.entry(root_of(entity)).or_insert((x, x));
            *e = (e.0.min(x), e.1.max(x));
        }
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
    /// selected, the side and time panels collapsed so that the plots have the window; each
    /// plot on the whole timeline with its own x axis, its legend by [`LEGEND_MAX`].
    pub fn layout(&self, path: &Path, panels: Vec<Panel>) -> Result<()> {
        let app = self.rec.store_info().map(|i| i.application_id().clone()).unwrap_or_else(|| "idrex".into());
        let (stream, storage) =
            rerun::RecordingStreamBuilder::new(app).recording_id(RecordingId::random()).blueprint().memory().map_err(|e| err(path, e))?;
        // What the viewer identifies blueprint data by; no wall-clock time in the layout.
        stream.set_log_time_enabled(false);
        stream.set_time_sequence("blueprint", 0);
        let counts = self.series.borrow();
        let mut children = Vec::new();
        // Fixed ids (views 1, 2, ...; the grid 0): the layout is the same in every recording.
        let id = |i: usize| uuid::Uuid::from_u128(0x1d4e_0000_0000_4000_8000_0000_0000_0000 | i as u128);
        for (i, panel) in panels.into_iter().enumerate() {
            let view = format!("view/{}", id(i + 1));
            let (class, title, origin, query) = match panel {
                Panel::Plot { title, root } => {
                    let n = counts.get(&root).copied().unwrap_or(0);
                    // What the panel plots first: the viewer (and `rerun rrd print`) cut a long title
                    // off at its end.
                    let title = if n > LEGEND_MAX { format!("{title} ({n} series, legend hidden: hover a point)") } else { title };
                    let (legend_visible, corner) = (n <= LEGEND_MAX, Corner2D::LeftTop);
                    // The x axis spans this view's data (Rerun's default is a window around
                    // the time cursor, which opens at the smallest x of any view).
                    let mut axis = bp::TimeAxis::new().with_link(LinkAxis::Independent);
                    if let Some(&(lo, hi)) = self.extent.borrow().get(&root) {
                        let pad = ((hi - lo) / 20).max(1);
                        let (start, end) = (TimeRangeBoundary::Absolute(TimeInt(lo - pad)), TimeRangeBoundary::Absolute(TimeInt(hi + pad)));
                        axis = axis.with_view_range(rerun::datatypes::TimeRange { start, end });
                    }
                    stream.log(format!("{view}/TimeAxis"), &axis).map_err(|e| err(path, e))?;
                    let whole = rerun::datatypes::VisibleTimeRange { timeline: X.into(), range: rerun::datatypes::TimeRange::EVERYTHING };
                    stream.log(format!("{view}/VisibleTimeRanges"), &bp::VisibleTimeRanges::new([whole])).map_err(|e| err(path, e))?;
                    stream
                        .log(format!("{view}/PlotLegend"), &bp::PlotLegend::new().with_corner(corner).with_visible(legend_visible))
                        .map_err(|e| err(path, e))?;
                    ("TimeSeries", title, "/".to_string(), format!("+ /{root}/**"))
                }
                Panel::Text { title, entity } => ("TextDocument", title, format!("/{entity}"), "$origin/**".to_string()),
            };
            stream
                .log(format!("{view}/ViewContents"), &bp::ViewContents::new([QueryExpression(query.into())]))
                .map_err(|e| err(path, e))?;
            let arch = bp::ViewBlueprint::new(ViewClass(class.into())).with_display_name(title).with_space_origin(origin);
            stream.log(view.as_str(), &arch).map_err(|e| err(path, e))?;
            children.push(IncludedContent(view.into()));
        }
        let container = id(0);
        let grid = bp::ContainerBlueprint::new(ContainerKind::Grid).with_contents(children);
        stream.log(format!("container/{container}"), &grid).map_err(|e| err(path, e))?;
        let viewport = bp::ViewportBlueprint::new()
            .with_root_container(RootContainer(container.into()))
            .with_auto_layout(false)
            .with_auto_views(false);
        stream.log("viewport", &viewport).map_err(|e| err(path, e))?;
        for panel in ["blueprint_panel", "selection_panel"] {
            stream.log(panel, &bp::PanelBlueprint::new().with_state(PanelState::Collapsed)).map_err(|e| err(path, e))?;
        }
        stream
            .log("time_panel", &bp::TimePanelBlueprint::new().with_timeline(X).with_state(PanelState::Collapsed))
            .map_err(|e| err(path, e))?;
        let msgs = storage.take();
        let blueprint_id = match msgs.first() {
            Some(rerun::log::LogMsg::SetStoreInfo(info)) => info.info.store_id.clone(),
            _ => return Err(err(path, "the blueprint stream did not start with its store info")),
        };
        let activation = BlueprintActivationCommand { blueprint_id, make_active: true, make_default: true };
        self.rec.send_blueprint(msgs, activation);
        Ok(())
    }

    /// Encodes the recording and writes it to `path` (fsynced).
    pub fn finish(self, path: &Path) -> Result<()> {
        let bytes = self.storage.drain_as_bytes().map_err(|e| err(path, e))?;
        std::fs::write(path, bytes).map_err(|e| Error::io(path, e))?;
        std::fs::File::open(path).and_then(|f| f.sync_all()).map_err(|e| Error::io(path, e))
    }
}
