//! The HTML report in a real browser: headless Chromium loads each page
//! with no console message and no script error, and screenshots show the
//! toolpath drawn (coloured pixels in every view), the worst block's red
//! ring where the JSON report puts that block, arcs (G2/G3 and `MoveC`)
//! through their arc's midpoint rather than along the chord, and a
//! drilling cycle's ring.
//!
//! Chromium is looked for as `$POSTPROC_CHROMIUM`, `chromium`,
//! `chromium-browser` or `google-chrome`. Without it the browser tests
//! pass with a note, except when `CI=true`: there they fail (`.ci/run`
//! installs the Debian package `chromium`).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{postproc, repo, write};

/// Window of the screenshots, CSS pixels (device scale factor 1).
const WINDOW: (u32, u32) = (1280, 1400);

/// Chromium, or `None` (a panic under `CI=true`: CI must run these tests).
fn chromium() -> Option<PathBuf> {
    let named = std::env::var_os("POSTPROC_CHROMIUM").map(PathBuf::from);
    let found = named.into_iter().chain(
        ["chromium", "chromium-browser", "google-chrome"]
            .iter()
            .filter_map(|n| {
                std::env::var_os("PATH").and_then(|path| {
                    std::env::split_paths(&path)
                        .map(|d| d.join(n))
                        .find(|p| p.is_file())
                })
            }),
    );
    let found = found.into_iter().find(|p| p.is_file());
    if found.is_none() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true and no chromium: the HTML report's browser tests cannot run \
             (apt-get install -y chromium, as .ci/run does)"
        );
        eprintln!("note: no chromium found; the HTML report's browser tests are not run");
    }
    found
}

/// Runs headless Chromium on a local page with `extra` arguments; gives
/// stdout and stderr.
fn browse(chrome: &Path, page: &Path, extra: &[String]) -> (String, String) {
    let profile = tempfile::tempdir().expect("profile dir");
    let url = format!("file://{}", page.display());
    let out = Command::new(chrome)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=5000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .arg(format!("--window-size={},{}", WINDOW.0, WINDOW.1))
        .args(extra)
        .arg(url)
        .output()
        .expect("chromium runs");
    (
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// The page's DOM after its script ran, checked for a clean load: no
/// console message (the page logs nothing), no script error recorded by
/// its error trap, and the script's end reached (`data-drawn`).
fn loaded_dom(chrome: &Path, page: &Path) -> String {
    let (dom, log) = browse(chrome, page, &["--dump-dom".into()]);
    let console: Vec<&str> = log.lines().filter(|l| l.contains(":CONSOLE")).collect();
    assert!(
        console.is_empty(),
        "{}: console messages:\n{}",
        page.display(),
        console.join("\n")
    );
    let errors = attr(&dom, "<html", "data-errors");
    assert!(
        errors.is_none(),
        "{}: script errors: {errors:?}",
        page.display()
    );
    let drawn = attr(&dom, "<body", "data-drawn").expect("the script ran to its end");
    assert!(drawn.parse::<usize>().expect("a count") > 0);
    dom
}

/// The value of attribute `name` of the first element starting with
/// `open` (`<canvas id="plan"`).
fn attr(dom: &str, open: &str, name: &str) -> Option<String> {
    let at = dom.find(open)?;
    let tag = &dom[at..at + dom[at..].find('>')?];
    let key = format!(" {name}=\"");
    let v = tag.find(&key)? + key.len();
    Some(tag[v..v + tag[v..].find('"')?].to_string())
}

/// Where a view draws a world point: the page's transform, read from its
/// canvas's data attributes.
#[derive(Debug, Clone, Copy)]
struct ViewMap {
    left: f64,
    top: f64,
    width: f64,
    height: f64,
    cu: f64,
    cv: f64,
    scale: f64,
    pan: (f64, f64),
}

impl ViewMap {
    fn of(dom: &str, id: &str) -> ViewMap {
        let open = format!("<canvas id=\"{id}\"");
        let get = |k: &str| -> f64 {
            attr(dom, &open, k)
                .unwrap_or_else(|| panic!("canvas {id} has {k}"))
                .parse()
                .expect("a number")
        };
        ViewMap {
            left: get("data-left"),
            top: get("data-top"),
            width: get("data-width"),
            height: get("data-height"),
            cu: get("data-cu"),
            cv: get("data-cv"),
            scale: get("data-scale"),
            pan: (get("data-pan-x"), get("data-pan-y")),
        }
    }

    /// Screenshot pixel of the view's coordinates (u, v) (plan: X, Y).
    fn pixel(&self, (u, v): (f64, f64)) -> (f64, f64) {
        (
            self.left + self.width / 2.0 + self.pan.0 + (u - self.cu) * self.scale,
            self.top + self.height / 2.0 + self.pan.1 - (v - self.cv) * self.scale,
        )
    }
}

/// An RGB screenshot.
struct Shot {
    w: usize,
    h: usize,
    rgb: Vec<u8>,
}

impl Shot {
    fn take(chrome: &Path, page: &Path) -> Shot {
        let dir = tempfile::tempdir().expect("temp dir");
        let png = dir.path().join("shot.png");
        let (_, log) = browse(chrome, page, &[format!("--screenshot={}", png.display())]);
        let file =
            std::fs::File::open(&png).unwrap_or_else(|e| panic!("no screenshot ({e}): {log}"));
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .expect("a PNG");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut buf).expect("a frame");
        let channels = info.color_type.samples();
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        let (w, h) = (info.width as usize, info.height as usize);
        let mut rgb = Vec::with_capacity(w * h * 3);
        for px in buf[..info.buffer_size()].chunks(channels) {
            rgb.extend_from_slice(&px[..3]);
        }
        // Kept for a look with an image viewer when a test fails.
        let keep = std::env::temp_dir().join(format!(
            "postproc-{}.png",
            page.file_stem().unwrap_or_default().to_string_lossy()
        ));
        let _ = std::fs::copy(&png, keep);
        Shot { w, h, rgb }
    }

    fn at(&self, x: i64, y: i64) -> Option<[u8; 3]> {
        if x < 0 || y < 0 || x as usize >= self.w || y as usize >= self.h {
            return None;
        }
        let i = (y as usize * self.w + x as usize) * 3;
        Some([self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]])
    }

    /// Pixels of the box of half-width `r` about `c` that pass `test`,
    /// with their mean position.
    fn count(&self, c: (f64, f64), r: i64, test: impl Fn([u8; 3]) -> bool) -> (usize, (f64, f64)) {
        let (cx, cy) = (c.0.round() as i64, c.1.round() as i64);
        let (mut n, mut sx, mut sy) = (0, 0.0, 0.0);
        for y in cy - r..=cy + r {
            for x in cx - r..=cx + r {
                if self.at(x, y).is_some_and(&test) {
                    n += 1;
                    sx += x as f64;
                    sy += y as f64;
                }
            }
        }
        let mean = if n > 0 {
            (sx / n as f64, sy / n as f64)
        } else {
            c
        };
        (n, mean)
    }

    /// Coloured pixels (a toolpath colour, not white, grey or black) in a
    /// view.
    fn coloured_in(&self, v: &ViewMap) -> usize {
        let mut n = 0;
        for y in v.top as i64..(v.top + v.height) as i64 {
            for x in v.left as i64..(v.left + v.width) as i64 {
                if self.at(x, y).is_some_and(coloured) {
                    n += 1;
                }
            }
        }
        n
    }
}

/// A saturated colour (the toolpath's viridis colours, the rings).
fn coloured(p: [u8; 3]) -> bool {
    let (max, min) = (
        p.iter().max().copied().unwrap_or(0),
        p.iter().min().copied().unwrap_or(0),
    );
    max - min > 40
}

/// The worst block's ring colour, `#ff0000`.
fn red(p: [u8; 3]) -> bool {
    p[0] >= 200 && p[1] <= 70 && p[2] <= 70
}

/// The hole ring's outline, `#222`.
fn dark(p: [u8; 3]) -> bool {
    p.iter().all(|&c| c <= 90)
}

/// Writes the HTML report of `program` on `machine` to `dir`.
fn html_report(dir: &Path, program: &Path, machine: &str) -> PathBuf {
    let out = dir.join(format!(
        "{}.html",
        program.file_stem().unwrap_or_default().to_string_lossy()
    ));
    postproc()
        .args(["report"])
        .arg(program)
        .args(["--machine", machine, "--format", "html", "-o"])
        .arg(&out)
        .assert()
        .success();
    out
}

/// The JSON report of `program`: the worst block's programmed (X, Y) and
/// every row's (line, X, Y, Z).
fn json_rows(program: &Path, machine: &str) -> (serde_json::Value, Vec<(u64, [f64; 3])>) {
    let a = postproc()
        .args(["report"])
        .arg(program)
        .args(["--machine", machine, "--format", "json"])
        .assert()
        .success();
    let v: serde_json::Value = serde_json::from_slice(&a.get_output().stdout).expect("JSON report");
    let rows = v["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| {
            let c = &r["commanded"];
            let f = |k: &str| c[k].as_f64().expect("a position");
            (
                r["line"].as_u64().expect("a line"),
                [f("X"), f("Y"), f("Z")],
            )
        })
        .collect();
    (v, rows)
}

/// The page of a bundled sample: loads cleanly, every view drawn, the
/// worst block's red ring where the JSON report puts it in plan view.
fn sample_page(sample: &str, machine: &str) {
    let page_src = std::fs::read_to_string(repo(sample)).expect("sample");
    assert!(!page_src.is_empty());
    let dir = tempfile::tempdir().expect("temp dir");
    let page = html_report(dir.path(), &repo(sample), machine);
    let html = std::fs::read_to_string(&page).expect("page");
    // Self-contained: nothing to fetch.
    for word in ["http://", "https://", " src=", "<link", "@import", "url("] {
        assert!(
            !html.contains(word),
            "{sample}: the page refers outside itself ({word})"
        );
    }
    let Some(chrome) = chromium() else {
        return;
    };
    let dom = loaded_dom(&chrome, &page);
    let shot = Shot::take(&chrome, &page);
    for id in ["plan", "side", "iso"] {
        let view = ViewMap::of(&dom, id);
        let n = shot.coloured_in(&view);
        assert!(n > 400, "{sample}: view {id} has {n} coloured pixels");
    }
    let (json, rows) = json_rows(&repo(sample), machine);
    let worst_line = json["summary"]["max_line"].as_u64().expect("max_line");
    let (_, at) = rows
        .iter()
        .find(|(l, _)| *l == worst_line)
        .expect("the worst line has a row");
    let plan = ViewMap::of(&dom, "plan");
    let want = plan.pixel((at[0], at[1]));
    let (n, mean) = shot.count(want, 14, red);
    assert!(
        n >= 40,
        "{sample}: {n} red pixels about {want:?} (worst line {worst_line})"
    );
    assert!(
        (mean.0 - want.0).abs() <= 2.0 && (mean.1 - want.1).abs() <= 2.0,
        "{sample}: the red ring is centred at {mean:?}, the worst block at {want:?}"
    );
}

#[test]
fn part_page_draws_and_marks_the_worst_block() {
    sample_page("samples/part.nc", "afm-r1000");
}

#[test]
fn drilling_page_draws_and_marks_the_worst_block() {
    sample_page("samples/drilling.mod", "abb-irb1600");
}

/// A half circle G2 from (10, 0) to (-10, 0) about the origin, then a
/// G81 hole at (30, 0) (part coordinates).
const ARC_NC: &str = "%\nO0100 (ARC AND HOLE)\nG90 G17 G21 G94 G40 G49 G80\nT1 M6\nS6000 M3\n\
G54 G0 X10. Y0.\nG43 Z5. H1\nG1 Z-1. F300.\nG2 X-10. Y0. I-10. J0. F600.\nG0 Z5.\n\
G99 G81 X30. Y0. Z-5. R2. F200.\nG80\nM5\nM30\n%\n";

#[test]
fn gcode_arcs_are_arcs_and_holes_are_rings() {
    let dir = tempfile::tempdir().expect("temp dir");
    let program = write(dir.path(), "arc.nc", ARC_NC);
    let page = html_report(dir.path(), &program, "afm-r1000");
    let (_, rows) = json_rows(&program, "afm-r1000");
    // Lines 8 (G1 down at the arc's start), 9 (the arc's end), 11 (the hole).
    let pos = |line: u64| rows.iter().find(|r| r.0 == line).expect("row").1;
    let (a, b, hole) = (pos(8), pos(9), pos(11));
    let centre = ((a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0);
    let radius = (a[0] - b[0]).abs() / 2.0;
    let Some(chrome) = chromium() else {
        return;
    };
    let dom = loaded_dom(&chrome, &page);
    let shot = Shot::take(&chrome, &page);
    let plan = ViewMap::of(&dom, "plan");
    // Clockwise from +X: through the -Y side of the centre; the chord
    // through the centre stays empty.
    let mid = plan.pixel((centre.0, centre.1 - radius));
    let (n, _) = shot.count(mid, 3, coloured);
    assert!(n >= 4, "nothing drawn at the arc's midpoint {mid:?}");
    let (n, _) = shot.count(plan.pixel(centre), 3, coloured);
    assert_eq!(n, 0, "the arc is drawn as its chord");
    let (n, _) = shot.count(plan.pixel((centre.0, centre.1 + radius)), 3, coloured);
    assert_eq!(n, 0, "the arc turns the wrong way");
    // The hole: a dark ring of radius 5 px about its centre.
    let h = plan.pixel((hole[0], hole[1]));
    let ring: usize = [(5.0, 0.0), (-5.0, 0.0), (0.0, 5.0), (0.0, -5.0)]
        .iter()
        .map(|(dx, dy)| shot.count((h.0 + dx, h.1 + dy), 1, dark).0)
        .sum();
    assert!(ring >= 4, "no ring about the hole at {h:?}");
}

/// A `MoveC` half circle about (700, 0, 400) from y = -100 through
/// (800, 0) to y = 100.
const ARC_MOD: &str = "MODULE ArcCell\n\
  PERS tooldata tPen := [TRUE,[[0,0,150],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]];\n\
  CONST robtarget pStart := [[700,-100,400],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
  CONST robtarget pVia := [[800,0,400],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
  CONST robtarget pEnd := [[700,100,400],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
\n  PROC main()\n    MoveJ pStart, v500, fine, tPen;\n    MoveC pVia, pEnd, v100, fine, tPen;\n  ENDPROC\nENDMODULE\n";

#[test]
fn move_c_is_an_arc_through_its_circle_point() {
    let dir = tempfile::tempdir().expect("temp dir");
    let program = write(dir.path(), "arccell.mod", ARC_MOD);
    let page = html_report(dir.path(), &program, "abb-irb1600");
    let html = std::fs::read_to_string(&page).expect("page");
    // The data carry the circle: centre (700, 0, 400) in µm, normal +Z,
    // sweep π.
    assert!(
        html.contains("\"arcs\":{\"1\":[700000,0,400000,0,0,1,3.141593]}"),
        "{}",
        &html[html.find("\"arcs\"").unwrap_or(0)..][..80.min(html.len())]
    );
    let Some(chrome) = chromium() else {
        return;
    };
    let dom = loaded_dom(&chrome, &page);
    let shot = Shot::take(&chrome, &page);
    let plan = ViewMap::of(&dom, "plan");
    let (n, _) = shot.count(plan.pixel((800.0, 0.0)), 3, coloured);
    assert!(n >= 4, "nothing drawn through the circle point");
    let (n, _) = shot.count(plan.pixel((700.0, 0.0)), 3, coloured);
    assert_eq!(n, 0, "the MoveC is drawn as its chord");
}

#[test]
fn a_long_program_is_kept_whole_up_to_ten_thousand_blocks_and_small() {
    // 10 000 feed blocks of a zigzag: every one drawn, the page a few
    // hundred kB.
    let mut nc = String::from(
        "%\nO0200\nG90 G17 G21 G94\nT1 M6\nS8000 M3\nG54 G0 X0. Y0.\nG43 Z5. H1\nG1 Z-1. F1000.\n",
    );
    for i in 0..10_000 {
        let x = (i % 100) as f64 * 1.5;
        let y = (i / 100) as f64 * 0.8 + if i % 2 == 0 { 0.0 } else { 0.4 };
        nc.push_str(&format!("X{x:.3}Y{y:.3}\n"));
    }
    nc.push_str("G0 Z5.\nM30\n%\n");
    let dir = tempfile::tempdir().expect("temp dir");
    let program = write(dir.path(), "long.nc", &nc);
    let page = html_report(dir.path(), &program, "afm-r1000");
    let html = std::fs::read_to_string(&page).expect("page");
    let data = &html[html.find("\"rows\":[").expect("rows")..];
    let rows = data[..data.find("]],").expect("end of rows")]
        .matches('[')
        .count()
        - 1;
    assert_eq!(rows, 10_000 + 4, "every move is kept");
    assert!(html.len() < 700_000, "the page is {} bytes", html.len());
}

#[test]
fn compensate_writes_the_page_for_an_html_report_path() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("part.out.nc");
    let page = dir.path().join("part.html");
    postproc()
        .arg("compensate")
        .arg(repo("samples/part.nc"))
        .args(["--machine", "afm-r1000", "-o"])
        .arg(&out)
        .arg("--report")
        .arg(&page)
        .assert()
        .success();
    let html = std::fs::read_to_string(&page).expect("page");
    assert!(
        html.starts_with("<!DOCTYPE html>"),
        "{}",
        &html[..40.min(html.len())]
    );
    assert!(html.contains("id=\"report-data\""));
    assert!(html.trim_end().ends_with("</html>"));
}

/// The block panel states U (k=2) where the machine file carries a
/// covariance: the page, with a script that clicks the first worst-block
/// link (what a reader does to keep a block), shows that block's U as the
/// JSON report gives it.
#[test]
fn the_block_panel_shows_u_from_the_covariance() {
    let dir = tempfile::tempdir().expect("temp dir");
    let machine = crate::report_uncertainty::machine_with_covariance(dir.path());
    let program = write(dir.path(), "p.nc", crate::report_uncertainty::PROGRAM);
    let page = html_report(dir.path(), &program, &machine.display().to_string());
    let Some(chrome) = chromium() else {
        return;
    };
    let html = std::fs::read_to_string(&page).expect("page");
    let click = "<script>document.querySelector(\"a.block\").click();</script></body>";
    let clicked = dir.path().join("clicked.html");
    std::fs::write(&clicked, html.replacen("</body>", click, 1)).expect("write");
    let dom = loaded_dom(&chrome, &clicked);
    let line: u64 = attr(&dom, "<a href=\"#\" class=\"block\"", "data-line")
        .and_then(|l| l.parse().ok())
        .expect("a worst-block link");
    let label = "U (k=2) of |deviation| (mm)</td><td>";
    let shown: f64 = dom
        .split(label)
        .nth(1)
        .and_then(|s| s.split('<').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no U in the block panel"));
    let (json, _) = json_rows(&program, &machine.display().to_string());
    let want = json["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["line"].as_u64() == Some(line))
        .and_then(|r| r["u_mm"].as_f64())
        .expect("the block's U");
    // The panel shows five decimals of a value kept to 0.1 µm.
    assert!(
        (shown - want).abs() <= 0.6e-4,
        "panel U {shown}, report {want}"
    );
}
