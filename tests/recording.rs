//! The Rerun recording as a user opens it, read back with Rerun's own `rerun rrd print`: every
//! plot view shows its whole timeline on its own x axis (so a view whose x is true returns
//! around -1,000 cannot hide a view whose x is environment steps), legends give way to the
//! data when a view holds many series, and every plotted row carries the plot timeline only.
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use idrex::log::rerun::{LEGEND_MAX, Panel, Recording, Style};

use crate::util::{TempDir, python, stderr};

/// Per entity: the data rows' text and the index (timeline) names of its chunks.
#[derive(Default, Debug)]
pub struct Entity {
    rows: String,
    timelines: BTreeSet<String>,
}

/// `rerun rrd print -vvv FILE`, parsed per entity.
pub fn printed(rrd: &Path) -> BTreeMap<String, Entity> {
    let rerun = Path::new(&python()).with_file_name("rerun");
    let p = Command::new(&rerun).args(["rrd", "print", "-vvv", rrd.to_str().unwrap()]).output().unwrap();
    assert!(p.status.success(), "rerun rrd print: {}", stderr(&p));
    let mut out: BTreeMap<String, Entity> = BTreeMap::new();
    let mut entity = String::new();
    for line in String::from_utf8_lossy(&p.stdout).lines() {
        if let Some(rest) = line.strip_prefix("Chunk(") {
            entity = rest.split(" - ").nth(1).unwrap_or_default().trim().to_string();
        } else if let Some(i) = line.find("index_name: ") {
            let name = line[i + 12..].split_whitespace().next().unwrap_or_default().to_string();
            out.entry(entity.clone()).or_default().timelines.insert(name);
        } else if line.contains("│ row_") {
            let e = out.entry(entity.clone()).or_default();
            e.rows.push_str(line);
            e.rows.push('\n');
        }
    }
    out
}

fn is_blueprint(e: &str) -> bool {
    ["/view/", "/container/", "/viewport", "/time_panel", "/blueprint_panel", "/selection_panel"].iter().any(|p| e.starts_with(p))
}

/// Checks a recording's layout: every time series view has its x axis independent of the
/// others (`TimeAxis:link` 1), the whole of timeline `x` visible, and its legend shown
/// exactly when it has few series (`legend_shown(title)`); no plotted row has another
/// timeline. Returns the views' titles.
pub fn check_layout(rrd: &Path, legend_shown: impl Fn(&str) -> bool) -> Vec<String> {
    let p = printed(rrd);
    let mut titles = Vec::new();
    for (e, v) in &p {
        let Some(id) = e.strip_prefix("/view/").filter(|id| !id.contains('/')) else { continue };
        let Some(title) =
            v.rows.split("[TimeSeries]").nth(1).map(|r| r.split('[').nth(1).unwrap_or("").split(']').next().unwrap().to_string())
        else {
            continue;
        };
        let prop = |name: &str| p.get(&format!("/view/{id}/{name}")).map(|x| x.rows.clone()).unwrap_or_default();
        assert!(prop("TimeAxis").contains("[1]"), "{title}: x axis not independent: {}", prop("TimeAxis"));
        assert!(prop("TimeAxis").contains("Absolute="), "{title}: x axis not set to the view's data: {}", prop("TimeAxis"));
        assert!(
            prop("VisibleTimeRanges").contains("{timeline: x, range: {start: {Infinite=null}, end: {Infinite=null}}}"),
            "{title}: not the whole timeline: {}",
            prop("VisibleTimeRanges")
        );
        let shown = if legend_shown(&title) { "[true]" } else { "[false]" };
        assert!(prop("PlotLegend").contains(shown), "{title}: legend should be {shown}: {}", prop("PlotLegend"));
        titles.push(title);
    }
    let plotted: BTreeSet<&String> = p.iter().filter(|(e, _)| !is_blueprint(e)).flat_map(|(_, v)| &v.timelines).collect();
    assert_eq!(plotted.into_iter().cloned().collect::<Vec<_>>(), vec!["x".to_string()], "plotted rows carry only the plot timeline");
    titles.sort();
    titles
}

/// A recording like a paper-settings run's: a scatter whose x (true returns) is all
/// negative, 15 PPO runs over a million steps, and a small panel.
#[test]
fn every_view_shows_its_data_and_legends_give_way() {
    let dir = TempDir::new("recording");
    let path = dir.join("many.rrd");
    let rec = Recording::create(&path, "many").unwrap();
    rec.series("reward/unseen", "unseen rollouts", Style::Points);
    for (i, t) in [-1050.0, -900.0, -640.5, -200.0].into_iter().enumerate() {
        rec.scalar("reward/unseen", t as i64, i as f64);
    }
    for run in 0..15 {
        let e = format!("ppo_true/run{run}");
        rec.series_coloured(&e, &format!("method {} run {run}", run / 3), Style::ThinLine, [10 * run as u8, 100, 200]);
        for step in (0..=1_000_000).step_by(250_000) {
            rec.scalar(&e, step, (step / 1000 + run) as f64);
        }
    }
    for leaf in ["a", "b", "c"] {
        rec.series(&format!("degradation/{leaf}"), leaf, Style::Line);
        rec.scalar(&format!("degradation/{leaf}"), 0, 1.0);
        rec.scalar(&format!("degradation/{leaf}"), 1000, 0.5);
    }
    rec.markdown("pipeline", "# stages");
    let plot = |title: &str, root: &str| Panel::Plot { title: title.into(), root: root.into() };
    rec.layout(
        &path,
        vec![
            plot("Learned against true return", "reward"),
            plot("PPO training episodes", "ppo_true"),
            plot("Return against noise level", "degradation"),
            Panel::Text { title: "Pipeline stages".into(), entity: "pipeline".into() },
        ],
    )
    .unwrap();
    rec.finish(&path).unwrap();
    const { assert!(15 > LEGEND_MAX) };
    let titles = check_layout(&path, |t| !t.contains(" series, legend"));
    assert_eq!(titles.len(), 3, "{titles:?}");
    let ppo = titles.iter().find(|t| t.contains("PPO")).unwrap();
    assert_eq!(ppo, "PPO training episodes (15 series, legend hidden: hover a point)", "what it plots first");
    assert!(titles.iter().filter(|t| t.contains("legend hidden")).count() == 1, "{titles:?}");
}
