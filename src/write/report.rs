//! The `convert --report` HTML report (`<stem>.report.html`): what smoothing did to each animated
//! bone, the per-sensor rate summary, the warnings and the dropped lines, in one self-contained
//! HTML5 document a person opens before importing the take.
//!
//! The report is pure: [`render_report`] takes the data ([`ReportInput`]) and returns the
//! document; the caller writes it (e.g. with [`crate::write::write_atomic`]).
//!
//! # The document
//!
//! - A header: take, source, frame rate, smoothing, number of animated bones.
//! - Warnings (each one a list item) and the number of dropped lines.
//! - The sensor table: per sensor the sample count, mean/min/max interval between samples in
//!   milliseconds and the gaps longer than [`GAP_THRESHOLD_S`].
//! - One chart per bone (inline SVG drawn with plotters' SVG backend): the three Euler angles in
//!   degrees over time in seconds, in the bone's channel order, each channel in its axis colour
//!   (X red, Y green, Z blue); before smoothing thin and light, after smoothing bold on top; a
//!   legend to the right of the plot names each curve (`Z before`, `Z after`, …). The caption says
//!   how far smoothing moved each channel at most. Each chart's `<figure class="bone">` carries
//!   `data-bone`, `data-order`, `data-plot-px` (the SVG coordinates `x0 y0 x1 y1` of the plot's
//!   corners (t0, v_min) and (t1, v_max)) and `data-plot-range` (`t0 v_min t1 v_max`), so that a
//!   tool can read the curves back in data units (tests/python/check_report.py does).
//!
//! Everything is inline (one `<style>`, no scripts, no external resources, no fonts: plotters'
//! SVG backend writes text as SVG `<text>` elements that the browser lays out), all text is
//! HTML-escaped, and the output depends only on the input (same input, same bytes).
//!
//! # Decimation
//!
//! A 60-minute take at 60 fps has 216 000 frames per channel; drawing them all would make the
//! report hundreds of megabytes for nothing, as a chart has only [`PLOT_WIDTH_PX`]-odd pixel
//! columns. Each curve is therefore reduced by min/max decimation ([`decimate_min_max`]): the time
//! span is cut into one bucket per pixel column of the plot area, and of each bucket only the
//! samples holding its minimum and its maximum are kept, in time order (one when they are the
//! same sample). A curve thus has at most two points per column (≤ 2 × the plot width, about
//! 1500 points), the drawn envelope is exactly that of the full data at the chart's resolution,
//! and a single-frame spike stays visible (it is its bucket's extreme). Curves that already have
//! no more than two points per column are drawn as they are. A 60-minute, 22-bone take at 60 fps
//! gives a report of about 1.7 MB.

use crate::anim::Animation;
use crate::inspect::{GAP_THRESHOLD_S, SensorSummaries};
use crate::rotation::EulerOrder;
use crate::rotation::euler::filter_track_degrees;
use nalgebra::UnitQuaternion;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::fmt::Write as _;

/// The width of a chart's SVG, pixels.
pub const CHART_WIDTH_PX: u32 = 960;
/// The height of a chart's SVG, pixels.
pub const CHART_HEIGHT_PX: u32 = 300;
/// The strip right of the plot holding the legend, pixels.
const LEGEND_WIDTH_PX: u32 = 130;
/// The label areas left of (y ticks and description) and below (x) the plot, pixels.
const Y_LABEL_AREA_PX: u32 = 70;
const X_LABEL_AREA_PX: u32 = 44;
const MARGIN_PX: u32 = 12;
/// The width of the plot area (pixel columns the curves are decimated to).
pub const PLOT_WIDTH_PX: u32 = CHART_WIDTH_PX - LEGEND_WIDTH_PX - Y_LABEL_AREA_PX - 2 * MARGIN_PX;

/// The colour of the curves of an axis (0 = x, 1 = y, 2 = z), as SVG writes it (`#RRGGBB`).
pub const AXIS_COLOURS: [&str; 3] = ["#D62728", "#2CA02C", "#1F77B4"];
const AXIS_RGB: [RGBColor; 3] = [
    RGBColor(0xD6, 0x27, 0x28),
    RGBColor(0x2C, 0xA0, 0x2C),
    RGBColor(0x1F, 0x77, 0xB4),
];
/// Stroke width and opacity of the curves before smoothing (thin, light) and after (bold).
pub const BEFORE_STROKE: (u32, f64) = (1, 0.5);
pub const AFTER_STROKE: (u32, f64) = (2, 1.0);

const FONT: &str = "sans-serif";
/// plotters writes `font-size` as this over 1.24: 15.5 → 12.5 px.
const FONT_SIZE: f64 = 15.5;

/// One animated bone's Euler angles before and after smoothing.
#[derive(Debug, Clone, PartialEq)]
pub struct BoneSeries {
    pub bone: String,
    /// The bone's channel order; the angles are in its application order (BVH channel order: for
    /// ZYX, `[z, y, x]`).
    pub order: EulerOrder,
    /// Frame times, seconds, ascending.
    pub times_s: Vec<f64>,
    /// Degrees, one entry per frame (made continuous by the caller). A series shorter or longer
    /// than `times_s` is drawn over the frames both have.
    pub before_deg: Vec<[f64; 3]>,
    pub after_deg: Vec<[f64; 3]>,
}

/// Everything the report shows.
#[derive(Debug, Clone)]
pub struct ReportInput<'a> {
    pub take: &'a str,
    pub source: &'a str,
    pub fps: String,
    /// e.g. `butterworth order 4, cutoff 6 Hz` or `none`.
    pub smoothing: String,
    pub bones: Vec<BoneSeries>,
    pub sensors: &'a SensorSummaries,
    pub warnings: &'a [String],
    pub dropped_lines: usize,
    /// Each fused sensor's id and what fusion came to (empty when nothing was fused).
    pub fusion: Vec<(&'a str, &'a crate::fusion::FusionStats)>,
}

/// Each animated bone's Euler angles (degrees, `[joint][frame]` in each joint's order) before
/// smoothing (`unsmoothed` local rotations, when kept; else the same as after) and after.
pub fn bone_series(
    animation: &Animation,
    unsmoothed: Option<&[Vec<UnitQuaternion<f64>>]>,
    euler_after: Option<&[Vec<[f64; 3]>]>,
) -> Vec<BoneSeries> {
    let fps = animation.fps();
    let times: Vec<f64> = (0..animation.frames() as u64)
        .map(|n| fps.frame_time_of(n))
        .collect();
    animation
        .rig()
        .joints()
        .iter()
        .enumerate()
        .filter(|(j, _)| animation.is_animated(*j))
        .map(|(j, joint)| {
            // The BVH's channels: given, or made from the rotations as the BVH writer makes them.
            let after_deg = match euler_after {
                Some(euler) => euler[j].clone(),
                None => filter_track_degrees(animation.local(j), joint.order),
            };
            BoneSeries {
                bone: joint.name.clone(),
                order: joint.order,
                times_s: times.clone(),
                before_deg: match unsmoothed {
                    Some(raw) => filter_track_degrees(&raw[j], joint.order),
                    None => after_deg.clone(),
                },
                after_deg,
            }
        })
        .collect()
}

/// The complete, self-contained HTML5 document (see the module documentation).
pub fn render_report(input: &ReportInput) -> String {
    let mut out = String::with_capacity(64 * 1024 + input.bones.len() * 100 * 1024);
    let take = escape(input.take);
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>imubake report: {take}</title>\n<style>\n{STYLE}</style>\n</head>\n<body>\n"
    );

    // Header.
    let _ = writeln!(out, "<header>\n<h1>imubake report: {take}</h1>");
    out.push_str("<dl class=\"summary\">\n");
    for (term, value) in [
        ("Take", input.take),
        ("Source", input.source),
        ("Frame rate", input.fps.as_str()),
        ("Smoothing", input.smoothing.as_str()),
    ] {
        let _ = writeln!(out, "<dt>{term}</dt><dd>{}</dd>", escape(value));
    }
    let _ = writeln!(
        out,
        "<dt>Animated bones</dt><dd>{}</dd>\n<dt>Dropped lines</dt><dd class=\"dropped\">{}</dd>",
        input.bones.len(),
        input.dropped_lines
    );
    out.push_str("</dl>\n</header>\n");

    // Warnings and dropped lines.
    let _ = writeln!(
        out,
        "<section id=\"warnings\">\n<h2>Warnings ({})</h2>",
        input.warnings.len()
    );
    if input.warnings.is_empty() {
        out.push_str("<p class=\"none\">No warnings.</p>\n");
    } else {
        out.push_str("<ul class=\"warnings\">\n");
        for w in input.warnings {
            let _ = writeln!(out, "<li>{}</li>", escape(w));
        }
        out.push_str("</ul>\n");
    }
    let _ = writeln!(
        out,
        "<p>Dropped lines (unreadable, not used): <span class=\"dropped\">{}</span></p>\n</section>",
        input.dropped_lines
    );

    // Sensors.
    sensor_table(&mut out, input.sensors);
    if !input.fusion.is_empty() {
        fusion_section(&mut out, &input.fusion);
    }

    // Bones.
    out.push_str(
        "<section id=\"bones\">\n<h2>Bones: Euler angles before and after smoothing</h2>\n",
    );
    let _ = writeln!(
        out,
        "<p class=\"note\">Each chart shows a bone's three Euler angles (degrees, in its channel \
         order) over time (seconds): before smoothing thin and light, after smoothing bold; X red, \
         Y green, Z blue. Long takes are drawn from the minimum and maximum of each pixel column \
         ({PLOT_WIDTH_PX} columns), so every spike stays visible.</p>"
    );
    if input.bones.is_empty() {
        out.push_str("<p class=\"none\">No animated bones.</p>\n");
    } else {
        out.push_str("<nav><ul>\n");
        for (i, b) in input.bones.iter().enumerate() {
            let _ = writeln!(
                out,
                "<li><a href=\"#bone-{i}\">{}</a></li>",
                escape(&b.bone)
            );
        }
        out.push_str("</ul></nav>\n");
    }
    for (i, bone) in input.bones.iter().enumerate() {
        bone_figure(&mut out, i, bone);
    }
    out.push_str("</section>\n");

    let _ = write!(
        out,
        "<footer>Written by imubake {}.</footer>\n</body>\n</html>\n",
        env!("CARGO_PKG_VERSION")
    );
    out
}

/// Min/max decimation of one curve for drawing onto `columns` pixel columns (see the module
/// documentation): the `(time, value)` points kept, in time order. Points with a non-finite time
/// or value are left out. When there are no more than `2 × columns` points, all are kept.
///
/// The time span (from the earliest to the latest time) is cut into `columns` equal buckets; of
/// each bucket the samples holding its minimum and its maximum value are kept (the first of equal
/// values; one point when the same sample is both), in the order they come in `times_s`, which
/// is expected ascending. `values` shorter or longer than `times_s`: the common length is used.
pub fn decimate_min_max(times_s: &[f64], values: &[f64], columns: usize) -> Vec<(f64, f64)> {
    let finite: Vec<usize> = (0..times_s.len().min(values.len()))
        .filter(|&i| times_s[i].is_finite() && values[i].is_finite())
        .collect();
    let columns = columns.max(1);
    if finite.len() <= 2 * columns {
        return finite.iter().map(|&i| (times_s[i], values[i])).collect();
    }
    let (t0, t1) = finite
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &i| {
            (a.min(times_s[i]), b.max(times_s[i]))
        });
    let span = t1 - t0;
    let bucket_of = |t: f64| {
        if span > 0.0 {
            (((t - t0) / span * columns as f64) as usize).min(columns - 1)
        } else {
            0
        }
    };
    // Per bucket: index of the minimum, index of the maximum.
    let mut buckets: Vec<Option<(usize, usize)>> = vec![None; columns];
    for &i in &finite {
        let v = values[i];
        let slot = &mut buckets[bucket_of(times_s[i])];
        match slot {
            None => *slot = Some((i, i)),
            Some((lo, hi)) => {
                if v < values[*lo] {
                    *lo = i;
                }
                if v > values[*hi] {
                    *hi = i;
                }
            }
        }
    }
    let mut out = Vec::with_capacity(2 * columns);
    for (lo, hi) in buckets.into_iter().flatten() {
        let (a, b) = (lo.min(hi), lo.max(hi));
        out.push((times_s[a], values[a]));
        if b != a {
            out.push((times_s[b], values[b]));
        }
    }
    out
}

/// HTML-escapes text for element content and quoted attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

const STYLE: &str = "\
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1000px; padding: 0 1em; color: #222; }
h1 { font-size: 1.5em; overflow-wrap: anywhere; }
h2 { font-size: 1.2em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }
h3 { font-size: 1.05em; margin: 0; overflow-wrap: anywhere; }
dl.summary { display: grid; grid-template-columns: max-content 1fr; gap: 0.2em 1em; }
dl.summary dt { font-weight: bold; }
dl.summary dd { margin: 0; overflow-wrap: anywhere; }
ul.warnings li { margin: 0.2em 0; overflow-wrap: anywhere; }
table.sensors { border-collapse: collapse; font-variant-numeric: tabular-nums; }
table.sensors th, table.sensors td { border: 1px solid #ccc; padding: 0.2em 0.6em; }
table.sensors td.num { text-align: right; }
table.sensors th { background: #f2f2f2; }
nav ul { list-style: none; padding: 0; display: flex; flex-wrap: wrap; gap: 0.3em 1em; }
figure.bone { margin: 1.2em 0; }
figure.bone p { margin: 0.2em 0; color: #555; font-size: 0.9em; }
figure.bone svg { max-width: 100%; height: auto; display: block; }
p.note, footer { color: #555; font-size: 0.9em; }
";

fn sensor_table(out: &mut String, sensors: &SensorSummaries) {
    let _ = writeln!(
        out,
        "<section id=\"sensors\">\n<h2>Sensors ({})</h2>",
        sensors.0.len()
    );
    if sensors.0.is_empty() {
        out.push_str("<p class=\"none\">No sensors.</p>\n</section>\n");
        return;
    }
    let _ = writeln!(
        out,
        "<table class=\"sensors\">\n<thead><tr><th>Sensor</th><th>Samples</th>\
         <th>Mean interval (ms)</th><th>Min interval (ms)</th><th>Max interval (ms)</th>\
         <th>First (s)</th><th>Last (s)</th><th>Gaps &gt; {GAP_THRESHOLD_S} s</th></tr></thead>\n<tbody>"
    );
    let ms = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.2}"));
    for (id, s) in &sensors.0 {
        let gaps = match s
            .gaps
            .iter()
            .map(|g| g.duration_s)
            .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))))
        {
            None => "0".to_string(),
            Some(longest) => format!("{} (longest {longest:.3} s)", s.gaps.len()),
        };
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{:.3}</td>\
             <td class=\"num\">{:.3}</td><td class=\"num\">{gaps}</td></tr>",
            escape(id),
            s.samples,
            ms(s.mean_dt_ms),
            ms(s.min_dt_ms),
            ms(s.max_dt_ms),
            s.first_s,
            s.last_s,
        );
    }
    out.push_str("</tbody>\n</table>\n</section>\n");
}

/// Per fused sensor a chart of the filter's gyro bias estimate (°/s) over time, with the spans in
/// which it set the magnetometer (red) or the accelerometer (orange) aside shaded behind it. Each
/// `<figure class="fusion">` carries `data-sensor`, `data-magnetic-rejected` and
/// `data-acceleration-rejected` (the shares of samples).
fn fusion_section(out: &mut String, fusion: &[(&str, &crate::fusion::FusionStats)]) {
    let _ = writeln!(
        out,
        "<section id=\"fusion\">\n<h2>Fusion ({} sensors)</h2>\n<p class=\"note\">Each chart shows \
         the filter's gyro bias estimate (°/s, blue) over time; shaded behind it, red where the \
         magnetometer was set aside as disturbed, orange where the accelerometer was.</p>",
        fusion.len()
    );
    for (sensor, stats) in fusion {
        let name = escape(sensor);
        let _ = writeln!(
            out,
            "<figure class=\"fusion\" data-sensor=\"{name}\" data-magnetic-rejected=\"{:.4}\" \
             data-acceleration-rejected=\"{:.4}\">\n<figcaption><h3>{name}</h3><p>{} {}, \
             magnetometer set aside in {:.1} % of the samples, accelerometer in {:.1} %{}{}.</p>\
             </figcaption>",
            stats.magnetic_rejected,
            stats.acceleration_rejected,
            stats.algorithm,
            stats.variant,
            100.0 * stats.magnetic_rejected,
            100.0 * stats.acceleration_rejected,
            stats.gyro_bias_dps.map_or(String::new(), |b| format!(
                "; final gyro bias ({:.3}, {:.3}, {:.3}) °/s",
                b[0], b[1], b[2]
            )),
            stats
                .expected_error_deg
                .map_or(String::new(), |e| format!("; expected error {e:.2}°")),
        );
        let mut svg = String::new();
        let drawn = {
            let root =
                SVGBackend::with_string(&mut svg, (CHART_WIDTH_PX, CHART_HEIGHT_PX / 2 + 60))
                    .into_drawing_area();
            let r = draw_fusion(&root, &stats.series);
            root.present().map_err(|e| e.to_string()).and(r)
        };
        match drawn {
            Ok(()) => out.push_str(&svg),
            Err(e) => {
                let _ = writeln!(
                    out,
                    "<p class=\"error\">The chart could not be drawn: {}</p>",
                    escape(&e)
                );
            }
        }
        out.push_str("</figure>\n");
    }
    out.push_str("</section>\n");
}

type Chart2d<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// The grid, ticks and axis descriptions every chart of the report has: time in seconds along x,
/// `y_desc` with about `y_labels` ticks up y.
fn draw_mesh(chart: &mut Chart2d<'_, '_>, y_desc: &str, y_labels: usize) -> Result<(), String> {
    let label_style = (FONT, FONT_SIZE).into_font().color(&BLACK.mix(0.8));
    chart
        .configure_mesh()
        .x_labels(10)
        .y_labels(y_labels)
        .x_desc("time (s)")
        .y_desc(y_desc)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .label_style(label_style.clone())
        .axis_desc_style(label_style)
        .bold_line_style(BLACK.mix(0.12))
        .max_light_lines(1)
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(|e| e.to_string())
}

fn draw_fusion(
    root: &DrawingArea<SVGBackend, Shift>,
    series: &[(f64, f64, bool, bool)],
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<std::io::Error>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let (t0, t1) = match (series.first(), series.last()) {
        (Some(a), Some(b)) if b.0 > a.0 => (a.0, b.0),
        (Some(a), _) => (a.0, a.0 + 1.0),
        _ => (0.0, 1.0),
    };
    let top = series
        .iter()
        .map(|s| s.1)
        .filter(|b| b.is_finite())
        .fold(0.0f64, f64::max)
        .max(0.1)
        * 1.1;
    let mut chart = ChartBuilder::on(root)
        .margin(MARGIN_PX)
        .x_label_area_size(X_LABEL_AREA_PX)
        .y_label_area_size(Y_LABEL_AREA_PX)
        .build_cartesian_2d(t0..t1, 0.0..top)
        .map_err(err)?;
    draw_mesh(&mut chart, "gyro bias (°/s)", 4)?;
    // Rejection spans: from a series point where it was set aside to the next point.
    for (band, colour, which) in [
        (0.5, RGBColor(0xD6, 0x27, 0x28), 2),
        (0.0, RGBColor(0xFF, 0x7F, 0x0E), 3),
    ] {
        let spans = series.windows(2).filter_map(|w| {
            let on = if which == 2 { w[0].2 } else { w[0].3 };
            on.then(|| {
                Rectangle::new(
                    [(w[0].0, top * band), (w[1].0, top * (band + 0.5))],
                    colour.mix(0.2).filled(),
                )
            })
        });
        chart.draw_series(spans).map_err(err)?;
    }
    let columns = chart.plotting_area().get_pixel_range().0.len();
    let times: Vec<f64> = series.iter().map(|s| s.0).collect();
    let bias: Vec<f64> = series.iter().map(|s| s.1).collect();
    chart
        .draw_series(LineSeries::new(
            decimate_min_max(&times, &bias, columns),
            AXIS_RGB[2].stroke_width(2),
        ))
        .map_err(err)?;
    Ok(())
}

/// The axis letter (`X`, `Y`, `Z`) of an axis index.
fn axis_letter(axis: usize) -> char {
    ['X', 'Y', 'Z'][axis]
}

/// Frames usable for drawing: the common length of times and both series.
fn frame_count(bone: &BoneSeries) -> usize {
    bone.times_s
        .len()
        .min(bone.before_deg.len())
        .min(bone.after_deg.len())
}

fn bone_figure(out: &mut String, index: usize, bone: &BoneSeries) {
    let n = frame_count(bone);
    let axes = bone.order.axes();
    // How far smoothing moved each channel at most.
    let mut moved = [0.0f64; 3];
    for f in 0..n {
        for (c, m) in moved.iter_mut().enumerate() {
            let d = (bone.after_deg[f][c] - bone.before_deg[f][c]).abs();
            if d.is_finite() {
                *m = m.max(d);
            }
        }
    }
    let moved: Vec<String> = (0..3)
        .map(|c| format!("{} {:.2}°", axis_letter(axes[c]), moved[c]))
        .collect();
    let duration = if n > 0 {
        bone.times_s[n - 1] - bone.times_s[0]
    } else {
        0.0
    };
    let chart = draw_chart(bone, n);
    let name = escape(&bone.bone);
    let order = bone.order.name();
    let (px, range) = match &chart {
        Ok(c) => (
            format!("{} {} {} {}", c.px.0, c.px.1, c.px.2, c.px.3),
            format!("{} {} {} {}", c.range.0, c.range.1, c.range.2, c.range.3),
        ),
        Err(_) => (String::new(), String::new()),
    };
    let _ = writeln!(
        out,
        "<figure class=\"bone\" id=\"bone-{index}\" data-bone=\"{name}\" data-order=\"{order}\" \
         data-plot-px=\"{px}\" data-plot-range=\"{range}\">\n\
         <figcaption><h3>{name}</h3><p>Channels {order}, {n} frames over {duration:.2} s; \
         smoothing moved {} at most.</p></figcaption>",
        moved.join(", ")
    );
    match chart {
        Ok(c) => out.push_str(&c.svg),
        Err(e) => {
            let _ = writeln!(
                out,
                "<p class=\"error\">The chart could not be drawn: {}</p>",
                escape(&e)
            );
        }
    }
    out.push_str("</figure>\n");
}

struct Chart {
    svg: String,
    /// SVG coordinates of (t0, v_min) and (t1, v_max): x0, y0, x1, y1.
    px: (i32, i32, i32, i32),
    /// t0, v_min, t1, v_max.
    range: (f64, f64, f64, f64),
}

/// The axis ranges of a bone's chart: times, then degrees with a 5 % margin.
fn ranges(bone: &BoneSeries, n: usize) -> ((f64, f64), (f64, f64)) {
    let finite = |v: &&f64| v.is_finite();
    let (mut t0, mut t1) = bone.times_s[..n]
        .iter()
        .filter(finite)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
            (a.min(t), b.max(t))
        });
    if t0 > t1 {
        (t0, t1) = (0.0, 1.0);
    } else if t1 - t0 <= 0.0 {
        t1 = t0 + 1.0;
    }
    let (mut lo, mut hi) = bone.before_deg[..n]
        .iter()
        .chain(&bone.after_deg[..n])
        .flatten()
        .filter(finite)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if lo > hi {
        (lo, hi) = (-1.0, 1.0);
    } else if hi - lo < 1e-6 {
        (lo, hi) = (lo - 1.0, hi + 1.0);
    } else {
        let pad = 0.05 * (hi - lo);
        (lo, hi) = (lo - pad, hi + pad);
    }
    ((t0, t1), (lo, hi))
}

/// A tick label: at most two decimals, no trailing zeros, no `-0`.
fn tick(v: f64) -> String {
    let s = format!("{v:.2}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".to_string() } else { s }
}

fn draw_chart(bone: &BoneSeries, n: usize) -> Result<Chart, String> {
    let mut svg = String::new();
    let (px, range) = {
        let root = SVGBackend::with_string(&mut svg, (CHART_WIDTH_PX, CHART_HEIGHT_PX))
            .into_drawing_area();
        let result = draw_on(&root, bone, n);
        root.present().map_err(|e| e.to_string())?;
        result?
    };
    Ok(Chart { svg, px, range })
}

type Geometry = ((i32, i32, i32, i32), (f64, f64, f64, f64));

fn draw_on(
    root: &DrawingArea<SVGBackend, Shift>,
    bone: &BoneSeries,
    n: usize,
) -> Result<Geometry, String> {
    let err = |e: DrawingAreaErrorKind<std::io::Error>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let (plot_area, legend_area) = root.split_horizontally(CHART_WIDTH_PX - LEGEND_WIDTH_PX);
    let ((t0, t1), (lo, hi)) = ranges(bone, n);
    let label_style = (FONT, FONT_SIZE).into_font().color(&BLACK.mix(0.8));
    let mut chart = ChartBuilder::on(&plot_area)
        .margin(MARGIN_PX)
        .x_label_area_size(X_LABEL_AREA_PX)
        .y_label_area_size(Y_LABEL_AREA_PX)
        .build_cartesian_2d(t0..t1, lo..hi)
        .map_err(err)?;
    draw_mesh(&mut chart, "angle (degrees)", 7)?;

    let columns = chart.plotting_area().get_pixel_range().0.len();
    let axes = bone.order.axes();
    let channel =
        |series: &[[f64; 3]], c: usize| -> Vec<f64> { series[..n].iter().map(|a| a[c]).collect() };
    for (series, (width, alpha)) in [
        (&bone.before_deg, BEFORE_STROKE),
        (&bone.after_deg, AFTER_STROKE),
    ] {
        for (c, &axis) in axes.iter().enumerate() {
            let points = decimate_min_max(&bone.times_s[..n], &channel(series, c), columns);
            let style = AXIS_RGB[axis].mix(alpha).stroke_width(width);
            chart
                .draw_series(LineSeries::new(points, style))
                .map_err(err)?;
        }
    }
    let (x0, y0) = chart.backend_coord(&(t0, lo));
    let (x1, y1) = chart.backend_coord(&(t1, hi));

    // The legend, in the strip right of the plot: one row per curve.
    let row_h = 22;
    let top = MARGIN_PX as i32 + 8;
    legend_area
        .draw(&Text::new(
            format!("channels {}", bone.order.name()),
            (4, top),
            label_style.clone(),
        ))
        .map_err(err)?;
    let mut row = 1;
    for &axis in &axes {
        for (what, (width, alpha)) in [("before", BEFORE_STROKE), ("after", AFTER_STROKE)] {
            let y = top + row * row_h;
            let style = AXIS_RGB[axis].mix(alpha).stroke_width(width);
            legend_area
                .draw(&PathElement::new(vec![(6, y + 6), (34, y + 6)], style))
                .map_err(err)?;
            legend_area
                .draw(&Text::new(
                    format!("{} {what}", axis_letter(axis)),
                    (42, y),
                    label_style.clone(),
                ))
                .map_err(err)?;
            row += 1;
        }
    }
    Ok(((x0, y0, x1, y1), (t0, lo, t1, hi)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_all_specials() {
        assert_eq!(escape("<script>&\"'x"), "&lt;script&gt;&amp;&quot;&#39;x");
        assert_eq!(escape("plain é"), "plain é");
    }

    #[test]
    fn decimation_keeps_short_series_whole() {
        let t: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let v: Vec<f64> = t.iter().map(|x| x * 2.0).collect();
        let d = decimate_min_max(&t, &v, 5);
        assert_eq!(d.len(), 10);
        assert_eq!(d[3], (3.0, 6.0));
        // Non-finite points are left out.
        let mut v2 = v.clone();
        v2[4] = f64::NAN;
        assert_eq!(decimate_min_max(&t, &v2, 5).len(), 9);
    }

    #[test]
    fn decimation_by_hand() {
        // 12 samples, 3 columns of 4: min and max of each, in time order.
        let t: Vec<f64> = (0..12).map(|i| i as f64).collect();
        let v = [
            0.0, 5.0, -1.0, 2.0, // bucket 0: max at 1, min at 2
            3.0, 3.0, 3.0, 3.0, // bucket 1: constant, one point
            9.0, 1.0, 1.0, 0.5, // bucket 2: max at 8, min at 11
        ];
        // Buckets: t in [0, 11] cut into thirds of 11/3: 0..3.67, 3.67..7.33, 7.33..11.
        let d = decimate_min_max(&t, &v, 3);
        assert_eq!(
            d,
            vec![(1.0, 5.0), (2.0, -1.0), (4.0, 3.0), (8.0, 9.0), (11.0, 0.5)]
        );
    }

    #[test]
    fn decimation_keeps_a_spike_and_bounds_points() {
        let n = 216_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let mut v: Vec<f64> = t.iter().map(|t| (t * 0.7).sin() * 20.0).collect();
        v[123_457] = 170.0;
        v[200_001] = -150.0;
        let d = decimate_min_max(&t, &v, PLOT_WIDTH_PX as usize);
        assert!(d.len() <= 2 * PLOT_WIDTH_PX as usize, "{}", d.len());
        assert!(d.contains(&(t[123_457], 170.0)));
        assert!(d.contains(&(t[200_001], -150.0)));
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0), "time order");
        // The envelope is the data's.
        let max = d.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        let min = d.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert_eq!((min, max), (-150.0, 170.0));
    }

    #[test]
    fn tick_labels() {
        assert_eq!(tick(0.0), "0");
        assert_eq!(tick(-0.001), "0");
        assert_eq!(tick(2.5), "2.5");
        assert_eq!(tick(-90.0), "-90");
        assert_eq!(tick(3600.0), "3600");
        assert_eq!(tick(0.375), "0.38");
    }

    fn small_input(sensors: &SensorSummaries) -> ReportInput<'_> {
        let times: Vec<f64> = (0..120).map(|i| i as f64 / 30.0).collect();
        let after: Vec<[f64; 3]> = times
            .iter()
            .map(|t| [10.0 * t.sin(), 5.0 * t.cos(), 1.0])
            .collect();
        let before = after
            .iter()
            .enumerate()
            .map(|(i, a)| [a[0] + if i % 2 == 0 { 2.0 } else { -2.0 }, a[1], a[2]])
            .collect();
        ReportInput {
            take: "walk <1>",
            source: "/data/a&b.csv",
            fps: "30".into(),
            smoothing: "none".into(),
            bones: vec![BoneSeries {
                bone: "Left\"Arm".into(),
                order: EulerOrder::ZXY,
                times_s: times,
                before_deg: before,
                after_deg: after,
            }],
            sensors,
            warnings: &[],
            dropped_lines: 3,
            fusion: Vec::new(),
        }
    }

    #[test]
    fn fused_sensors_get_a_chart_with_their_rejection_spans() {
        let sensors = SensorSummaries(Default::default());
        // Bias settling to 0.3 °/s; the magnetometer set aside from 2 s to 3 s.
        let series: Vec<(f64, f64, bool, bool)> = (0..50)
            .map(|i| {
                let t = i as f64 * 0.1;
                (t, 0.3 * (1.0 - (-t).exp()), (2.0..3.0).contains(&t), false)
            })
            .collect();
        let stats = crate::fusion::FusionStats {
            algorithm: "offline",
            variant: "9d",
            filled_samples: 0,
            gyro_bias_dps: Some([0.1, -0.2, 0.2]),
            magnetic_rejected: 0.2,
            acceleration_rejected: 0.0,
            rest_s: Some(1.5),
            disturbed_s: Some(0.4),
            expected_error_deg: Some(0.75),
            corrections: Vec::new(),
            series,
        };
        let mut input = small_input(&sensors);
        input.fusion = vec![("thigh <L>", &stats)];
        let html = render_report(&input);
        assert!(html.contains("<section id=\"fusion\">"));
        assert!(html.contains(
            "data-sensor=\"thigh &lt;L&gt;\" data-magnetic-rejected=\"0.2000\" data-acceleration-rejected=\"0.0000\""
        ));
        assert!(html.contains("offline 9d, magnetometer set aside in 20.0 % of the samples"));
        assert!(html.contains("; expected error 0.75°."));
        let figure = &html[html.find("class=\"fusion\"").unwrap()..];
        let svg = &figure[..figure.find("</svg>").unwrap()];
        // Ten 0.1 s spans shaded (2.0 … 2.9 s), over the mesh's own rectangles.
        let shaded = svg.matches("opacity=\"0.2\" fill=\"#D62728\"").count();
        assert_eq!(shaded, 10, "{svg}");
        // Without fused sensors there is no such section.
        assert!(!render_report(&small_input(&sensors)).contains("id=\"fusion\""));
    }

    #[test]
    fn document_is_deterministic_and_escaped() {
        let sensors = SensorSummaries(vec![(
            "s<1>".into(),
            crate::inspect::SensorSummary::from_times(&[0.0, 0.01, 0.5]),
        )]);
        let input = small_input(&sensors);
        let a = render_report(&input);
        let b = render_report(&input);
        assert_eq!(a, b);
        assert!(a.starts_with("<!DOCTYPE html>\n"));
        assert!(a.ends_with("</html>\n"));
        assert!(a.contains("walk &lt;1&gt;"));
        assert!(a.contains("/data/a&amp;b.csv"));
        assert!(a.contains("data-bone=\"Left&quot;Arm\""));
        assert!(a.contains("<td>s&lt;1&gt;</td>"));
        assert!(a.contains("1 (longest 0.490 s)"));
        assert!(a.contains("<span class=\"dropped\">3</span>"));
        assert!(!a.contains("<script"));
        // No external resources: the only URL is the SVG namespace.
        assert!(!a.contains(" src=") && !a.contains("href=\"http") && !a.contains("url("));
        assert_eq!(a.matches("<svg").count(), 1);
        // The legend names the curves with the order's axis letters.
        for label in [
            "Z before", "Z after", "X before", "X after", "Y before", "Y after",
        ] {
            assert!(a.contains(label), "{label}");
        }
        // Six curves plus six legend samples, in the axis colours.
        let coloured = AXIS_COLOURS
            .iter()
            .map(|c| a.matches(&format!("stroke=\"{c}\"")).count())
            .sum::<usize>();
        assert_eq!(coloured, 12);
    }

    #[test]
    fn degenerate_bones_still_draw() {
        let sensors = SensorSummaries::default();
        let mut input = small_input(&sensors);
        input.bones[0].times_s = vec![];
        input.bones.push(BoneSeries {
            bone: "One".into(),
            order: EulerOrder::XYZ,
            times_s: vec![0.0],
            before_deg: vec![[1.0, 2.0, f64::NAN]],
            after_deg: vec![[1.0, 2.0, 3.0]],
        });
        let html = render_report(&input);
        assert_eq!(html.matches("<svg").count(), 2);
        assert!(!html.contains("class=\"error\""));
        assert!(html.contains("No sensors."));
    }
}
