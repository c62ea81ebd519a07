//! The accuracy plot: mean error against bake time, log-log, each merge setting in its colour,
//! with the Pareto front of this sweep and, in grey, of the earlier ones.

use std::fmt::Write as _;

use super::{front, Point, MERGES};
use crate::plot::escape;

/// Log-log axes of a plot: data ranges mapped into a `w` x `h` canvas with margin `m`.
struct Axes {
    x: (f64, f64),
    y: (f64, f64),
    w: f64,
    h: f64,
    m: f64,
}

impl Axes {
    fn sx(&self, ms: f64) -> f64 {
        let (x0, x1) = self.x;
        self.m + (ms.log10() - x0) / (x1 - x0).max(1e-9) * (self.w - 2.0 * self.m)
    }

    fn sy(&self, percent: f64) -> f64 {
        let (y0, y1) = self.y;
        self.h - self.m - (percent.log10() - y0) / (y1 - y0).max(1e-9) * (self.h - 2.0 * self.m)
    }

    /// Axis lines and ticks at 1, 2 and 5 times the powers of ten inside the ranges.
    fn draw(&self, s: &mut String) {
        let (w, h, m) = (self.w, self.h, self.m);
        let _ = writeln!(s, "<line x1='{m}' y1='{}' x2='{}' y2='{}' stroke='black'/><line x1='{m}' y1='{m}' x2='{m}' y2='{}' stroke='black'/>", h - m, w - m, h - m, h - m);
        // Over more than three decades, 2 and 5 crowd the labels: powers of ten only.
        let ticks = |(lo, hi): (f64, f64)| {
            let steps: &[f64] = if hi - lo > 3.0 {
                &[1.0]
            } else {
                &[1.0, 2.0, 5.0]
            };
            (lo.floor() as i32..=hi.ceil() as i32)
                .flat_map(move |e| steps.iter().map(move |k| k * 10f64.powi(e)))
                .filter(move |v| (lo..=hi).contains(&v.log10()))
        };
        for v in ticks(self.x) {
            let x = self.sx(v);
            let label = if v >= 1000.0 {
                format!("{} s", v / 1000.0)
            } else {
                format!("{v} ms")
            };
            let _ = writeln!(s, "<line x1='{x:.1}' y1='{}' x2='{x:.1}' y2='{}' stroke='#ddd'/><text x='{x:.1}' y='{}' text-anchor='middle'>{label}</text>", m, h - m, h - m + 16.0);
        }
        for v in ticks(self.y) {
            let y = self.sy(v);
            let _ = writeln!(s, "<line x1='{m}' y1='{y:.1}' x2='{}' y2='{y:.1}' stroke='#ddd'/><text x='{}' y='{:.1}' text-anchor='end'>{v}%</text>", w - m, m - 4.0, y + 4.0);
        }
    }

    /// The front of `points` as a polyline.
    fn polyline(&self, points: &[&Point], style: &str) -> String {
        let xy: Vec<String> = points
            .iter()
            .map(|p| format!("{:.1},{:.1}", self.sx(p.bake_ms), self.sy(p.error)))
            .collect();
        format!(
            "<polyline points='{}' fill='none' {style}/>\n",
            xy.join(" ")
        )
    }
}

/// SVG scatter of mean error against bake time, log-log, with the Pareto front, and the front
/// of the previous sweeps (grey) when given.
pub(super) fn plot(new: &[Point], previous: &[Point], caption: &str) -> String {
    let range = |f: fn(&Point) -> f64| {
        new.iter()
            .chain(previous)
            .map(f)
            .filter(|v| *v > 0.0)
            .fold((f64::MAX, f64::MIN), |(a, b), v| {
                (a.min(v.log10()), b.max(v.log10()))
            })
    };
    // A margin of a few hundredths of a decade keeps the extreme points inside the frame.
    let pad = |(lo, hi): (f64, f64), by: f64| (lo - by, hi + by);
    let axes = Axes {
        x: pad(range(|p| p.bake_ms), 0.03),
        y: pad(range(|p| p.error), 0.04),
        w: 760.0,
        h: 480.0,
        m: 60.0,
    };
    let (w, m) = (axes.w, axes.m);
    let mut s = format!("<svg xmlns='http://www.w3.org/2000/svg' width='{w}' height='{}' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n", axes.h);
    let _ = writeln!(s, "<text x='{}' y='20' text-anchor='middle' font-size='14'>Mean irradiance error against bake time (log-log)</text>", w / 2.0);
    let _ = writeln!(
        s,
        "<text x='{}' y='38' text-anchor='middle' font-size='10' fill='#555'>{}</text>",
        w / 2.0,
        escape(caption)
    );
    axes.draw(&mut s);
    let shown = |p: &&Point| p.bake_ms > 0.0 && p.error > 0.0;
    let previous_front: Vec<&Point> = front(previous).into_iter().filter(shown).collect();
    if !previous_front.is_empty() {
        s.push_str(&axes.polyline(
            &previous_front,
            "stroke='#999' stroke-width='2' stroke-dasharray='6 4'",
        ));
        for p in &previous_front {
            let _ = writeln!(s, "<rect x='{:.1}' y='{:.1}' width='7' height='7' fill='#999'><title>previous: {}: {:.1} ms, {:.2}%</title></rect>", axes.sx(p.bake_ms) - 3.5, axes.sy(p.error) - 3.5, escape(&p.setting), p.bake_ms, p.error);
        }
    }
    let new_front: Vec<&Point> = front(new).into_iter().filter(shown).collect();
    s.push_str(&axes.polyline(&new_front, "stroke='#222' stroke-width='1.5'"));
    for p in new.iter().filter(shown) {
        let shape = if p.flat {
            "fill='none' stroke-width='1.5' stroke"
        } else {
            "fill"
        };
        let _ = writeln!(s, "<circle cx='{:.1}' cy='{:.1}' r='4' {shape}='{}'><title>{}: {:.1} ms, {:.2}%</title></circle>", axes.sx(p.bake_ms), axes.sy(p.error), merge_color(&p.merge), escape(&p.setting), p.bake_ms, p.error);
    }
    legend(&mut s, w - 200.0, m, !previous_front.is_empty());
    s.push_str("</svg>\n");
    s
}

/// The plot's legend, its left edge at `x`, from `top` down.
fn legend(s: &mut String, x: f64, top: f64, previous: bool) {
    for (i, (merge, ..)) in MERGES.iter().enumerate() {
        let y = top + 16.0 * i as f64;
        let _ = writeln!(
            s,
            "<circle cx='{x}' cy='{y}' r='4' fill='{}'/><text x='{}' y='{}'>bricks: {merge}</text>",
            merge_color(merge),
            x + 10.0,
            y + 4.0
        );
    }
    let mut lines = vec!["hollow: flat brick radiance", "solid line: Pareto front"];
    if previous {
        lines.push("grey dashed: previous front");
    }
    for (i, text) in lines.iter().enumerate() {
        let _ = writeln!(
            s,
            "<text x='{x}' y='{}'>{text}</text>",
            top + 16.0 * (MERGES.len() + 1 + i) as f64
        );
    }
}

/// The colour of a brick size's points.
fn merge_color(merge: &str) -> &'static str {
    // "spacing/8 (default)": the size without the note.
    match merge.split(' ').next().unwrap_or(merge) {
        "none" => "#d62728",
        "spacing/24" => "#1f77b4",
        "spacing/6" => "#2ca02c",
        "spacing/12" => "#9467bd",
        _ => "#ff7f0e",
    }
}
