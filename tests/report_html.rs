//! `idrex report --format html` on the smoke pipeline's store: one self-contained page that
//! headless Chromium (Debian's package; `scripts/services.sh install` brings it) renders, with
//! its figures drawn. Whether the figures render is read from the screenshots: the same page
//! with its figures cut out must lose nearly all of its coloured pixels.
use std::path::Path;
use std::process::Command;

use crate::util::{TempDir, idrex, python, repo, stderr};

fn chromium() -> Option<String> {
    ["chromium", "chromium-browser"]
        .into_iter()
        .find(|c| Command::new(c).arg("--version").output().is_ok_and(|o| o.status.success()))
        .map(String::from)
}

/// Pixels of a strong colour (the plots' lines and points; the tables are grey on white).
fn coloured_pixels(png: &Path) -> u64 {
    let code = "from PIL import Image; import sys\nim = Image.open(sys.argv[1]).convert('RGB')\n\
                print(sum(1 for p in im.getdata() if max(p) - min(p) > 80))";
    let out = Command::new(python()).args(["-c", code, png.to_str().unwrap()]).output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    String::from_utf8_lossy(&out.stdout).trim().parse().unwrap()
}

fn screenshot(browser: &str, page: &Path, png: &Path) {
    let out = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--window-size=1280,4000"])
        .arg(format!("--screenshot={}", png.display()))
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    assert!(out.status.success() && png.exists(), "{}", stderr(&out));
}

#[test]
fn the_html_report_is_one_page_that_renders_in_headless_chromium() {
    let dir = TempDir::new("html");
    let (store, rec, out) = (dir.join("store"), dir.join("smoke.rrd"), dir.join("report"));
    let smoke = repo("pipelines/smoke.yaml");
    let run =
        idrex(&["pipeline", "run", smoke.to_str().unwrap(), "--store", store.to_str().unwrap(), "--recording", rec.to_str().unwrap()]);
    assert!(run.status.success(), "{}", stderr(&run));
    let rep = idrex(&[
        "report",
        "--store",
        store.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--format",
        "html",
        "--figures",
        "svg",
        "--recording",
        rec.to_str().unwrap(),
    ]);
    assert!(rep.status.success(), "{}", stderr(&rep));
    let page = out.join("report.html");
    let html = std::fs::read_to_string(&page).unwrap();
    // Self-contained: no element that loads anything (a link is followed only when clicked).
    for load in ["<link", "<script src", "<img src=\"http", "<iframe", "@import", "url(", "xlink:href=\"http"] {
        assert!(!html.contains(load), "the page loads `{load}`");
    }
    // The answer first, tables sortable, figures inline, details folded, files linked.
    assert!(html.find("The answer").unwrap() < html.find("<table").unwrap());
    assert!(html.matches("<table class=\"sortable\">").count() >= 5);
    assert!(html.matches("<figure><svg").count() >= 3, "figures inline as SVG");
    assert!(html.contains("<details><summary>Multi-BC clones against their sources"));
    assert!(html.contains("<details><summary>Three protocols"));
    assert!(html.contains(".mcap\">rollouts.mcap</a>") && html.contains("smoke.rrd\">"));

    let Some(browser) = chromium() else {
        assert!(std::env::var_os("IDREX_REQUIRE_SERVICES").is_none(), "no chromium: run scripts/services.sh install");
        crate::util::skip("report_html::(the screenshots)", "no chromium here (scripts/services.sh install brings it)");
        return;
    };
    let shot = dir.join("page.png");
    screenshot(&browser, &page, &shot);
    let bare = dir.join("bare.html");
    let mut cut = String::new();
    let mut rest = html.as_str();
    while let Some(a) = rest.find("<figure>") {
        cut.push_str(&rest[..a]);
        rest = &rest[a + rest[a..].find("</figure>").unwrap() + "</figure>".len()..];
    }
    cut.push_str(rest);
    std::fs::write(&bare, cut).unwrap();
    let bare_shot = dir.join("bare.png");
    screenshot(&browser, &bare, &bare_shot);
    let (with, without) = (coloured_pixels(&shot), coloured_pixels(&bare_shot));
    assert!(with > 5_000 && with > 10 * without.max(1), "coloured pixels: {with} with the figures, {without} without");
}
