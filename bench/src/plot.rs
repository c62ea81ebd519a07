//! Log-log scatter plots as SVG, side by side in panels, with each panel's Pareto front (the
//! points no other point beats on both axes): what `prt-bench frontier` draws. Plain SVG text,
//! so the pictures diff in review and need no plotting crate.

use std::fmt::Write as _;

/// One point: where, and what its tooltip and label say.
pub struct Point {
    pub x: f64,
    pub y: f64,
    /// Written beside the point (short: a spacing, a setting).
    pub label: String,
    /// The tooltip (the whole setting and its values).
    pub title: String,
}

/// Points drawn in one colour, named in the legend.
pub struct Series {
    pub name: String,
    pub color: &'static str,
    pub points: Vec<Point>,
}

/// One plot: its axes' names and units, and its series.
pub struct Panel {
    pub title: String,
    pub x_name: String,
    /// Appended to the x tick values (" MB", " s").
    pub x_unit: &'static str,
    pub y_name: String,
    /// Appended to the y tick values ("%").
    pub y_unit: &'static str,
    pub series: Vec<Series>,
}

const PANEL_W: f64 = 560.0;
const PANEL_H: f64 = 420.0;
const MARGIN: f64 = 64.0;
const HEADER: f64 = 48.0;

/// The items that no other item beats on both `x` and `y` (lower is better on each), in order
/// of `x`: the Pareto front (`prt-bench accuracy`'s error against bake time, and the plots').
pub fn front_by<'a, T>(
    items: impl IntoIterator<Item = &'a T>,
    x: fn(&T) -> f64,
    y: fn(&T) -> f64,
) -> Vec<&'a T> {
    let mut sorted: Vec<&T> = items.into_iter().collect();
    sorted.sort_by(|a, b| x(a).total_cmp(&x(b)).then(y(a).total_cmp(&y(b))));
    let mut out: Vec<&T> = Vec::new();
    for p in sorted {
        if out.last().is_none_or(|q| y(p) < y(q)) {
            out.push(p);
        }
    }
    out
}

/// The front ([`front_by`]) of `points` that a log-log plot can draw: a point at or below zero
/// is not drawn, so it is no part of the front either.
pub fn front<'a>(points: &[&'a Point]) -> Vec<&'a Point> {
    let drawn = points.iter().copied().filter(|p| p.x > 0.0 && p.y > 0.0);
    front_by(drawn, |p| p.x, |p| p.y)
}

/// `panels` side by side under `title` and a one-line `caption`.
pub fn svg(title: &str, caption: &str, panels: &[Panel]) -> String {
    let w = PANEL_W * panels.len().max(1) as f64;
    let h = PANEL_H + HEADER;
    let mut s = format!(
        "<svg xmlns='http://www.w3.org/2000/svg' width='{w}' height='{h}' font-family='sans-serif' font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n"
    );
    let _ = writeln!(
        s,
        "<text x='{}' y='20' text-anchor='middle' font-size='15'>{}</text>",
        w / 2.0,
        escape(title)
    );
    let _ = writeln!(
        s,
        "<text x='{}' y='38' text-anchor='middle' font-size='11' fill='#555'>{}</text>",
        w / 2.0,
        escape(caption)
    );
    for (i, panel) in panels.iter().enumerate() {
        let _ = writeln!(
            s,
            "<g transform='translate({},{HEADER})'>",
            PANEL_W * i as f64
        );
        draw_panel(&mut s, panel);
        s.push_str("</g>\n");
    }
    s.push_str("</svg>\n");
    s
}

/// Log10 range of `values` (positive ones), padded by a few hundredths of a decade.
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold((f64::MAX, f64::MIN), |(a, b), v| {
            (a.min(v.log10()), b.max(v.log10()))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    let pad = 0.04 + 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Ticks at 1, 2 and 5 times the powers of ten inside a log10 range (powers of ten alone over
/// more than three decades, every digit within less than one).
fn ticks((lo, hi): (f64, f64)) -> Vec<f64> {
    let steps: &[f64] = if hi - lo > 3.0 {
        &[1.0]
    } else if hi - lo > 1.0 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    };
    (lo.floor() as i32..=hi.ceil() as i32)
        .flat_map(|e| steps.iter().map(move |k| k * 10f64.powi(e)))
        .filter(|v| (lo..=hi).contains(&v.log10()))
        .collect()
}

/// A tick value without trailing zeros.
fn number(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

fn draw_panel(s: &mut String, panel: &Panel) {
    let points: Vec<&Point> = panel.series.iter().flat_map(|r| &r.points).collect();
    let xr = range(points.iter().map(|p| p.x));
    let yr = range(points.iter().map(|p| p.y));
    let (w, h, m) = (PANEL_W, PANEL_H, MARGIN);
    let sx = |x: f64| m + (x.log10() - xr.0) / (xr.1 - xr.0) * (w - 1.5 * m);
    let sy = |y: f64| h - m - (y.log10() - yr.0) / (yr.1 - yr.0) * (h - 1.6 * m);
    let _ = writeln!(
        s,
        "<text x='{}' y='14' text-anchor='middle' font-size='13'>{}</text>",
        w / 2.0,
        escape(&panel.title)
    );
    let _ = writeln!(s, "<line x1='{m}' y1='{}' x2='{}' y2='{}' stroke='black'/><line x1='{m}' y1='{}' x2='{m}' y2='{}' stroke='black'/>", h - m, w - 0.5 * m, h - m, 0.6 * m, h - m);
    for v in ticks(xr) {
        let x = sx(v);
        let _ = writeln!(s, "<line x1='{x:.1}' y1='{}' x2='{x:.1}' y2='{}' stroke='#ddd'/><text x='{x:.1}' y='{}' text-anchor='middle'>{}{}</text>", 0.6 * m, h - m, h - m + 16.0, number(v), panel.x_unit);
    }
    for v in ticks(yr) {
        let y = sy(v);
        let _ = writeln!(s, "<line x1='{m}' y1='{y:.1}' x2='{}' y2='{y:.1}' stroke='#ddd'/><text x='{}' y='{:.1}' text-anchor='end'>{}{}</text>", w - 0.5 * m, m - 6.0, y + 4.0, number(v), panel.y_unit);
    }
    let _ = writeln!(
        s,
        "<text x='{}' y='{}' text-anchor='middle'>{}</text>",
        (m + w - 0.5 * m) / 2.0,
        h - m + 36.0,
        escape(&panel.x_name)
    );
    let _ = writeln!(
        s,
        "<text x='14' y='{}' text-anchor='middle' transform='rotate(-90 14 {})'>{}</text>",
        h / 2.0,
        h / 2.0,
        escape(&panel.y_name)
    );
    let best = front(&points);
    let line: Vec<String> = best
        .iter()
        .map(|p| format!("{:.1},{:.1}", sx(p.x), sy(p.y)))
        .collect();
    let _ = writeln!(
        s,
        "<polyline points='{}' fill='none' stroke='#222' stroke-width='1.5' stroke-dasharray='5 3'/>",
        line.join(" ")
    );
    for series in &panel.series {
        for p in series.points.iter().filter(|p| p.x > 0.0 && p.y > 0.0) {
            let (x, y) = (sx(p.x), sy(p.y));
            let _ = writeln!(s, "<circle cx='{x:.1}' cy='{y:.1}' r='4.5' fill='{}'><title>{}</title></circle><text x='{:.1}' y='{:.1}' font-size='10' fill='#444'>{}</text>", series.color, escape(&p.title), x + 6.0, y - 5.0, escape(&p.label));
        }
    }
    for (i, series) in panel.series.iter().enumerate() {
        let y = 0.6 * m + 10.0 + 16.0 * i as f64;
        let x = w - 3.6 * m;
        let _ = writeln!(
            s,
            "<circle cx='{x}' cy='{y}' r='4.5' fill='{}'/><text x='{}' y='{}'>{}</text>",
            series.color,
            x + 9.0,
            y + 4.0,
            escape(&series.name)
        );
    }
    let y = 0.6 * m + 10.0 + 16.0 * panel.series.len() as f64;
    let _ = writeln!(
        s,
        "<text x='{}' y='{}' fill='#444'>dashed: the front</text>",
        w - 3.6 * m - 5.0,
        y + 4.0
    );
}

/// `text` with the characters XML gives a meaning escaped.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('\'', "&apos;")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(x: f64, y: f64) -> Point {
        Point {
            x,
            y,
            label: String::new(),
            title: format!("{x} {y}"),
        }
    }

    #[test]
    fn the_front_keeps_what_nothing_beats_on_both_axes() {
        let points = [
            point(3.0, 5.0),
            point(1.0, 9.0),
            point(2.0, 10.0),
            point(4.0, 1.0),
        ];
        let refs: Vec<&Point> = points.iter().collect();
        let f: Vec<(f64, f64)> = front(&refs).iter().map(|p| (p.x, p.y)).collect();
        assert_eq!(f, vec![(1.0, 9.0), (3.0, 5.0), (4.0, 1.0)]);
    }

    #[test]
    fn an_svg_names_its_panels_and_escapes_text() {
        let panel = Panel {
            title: "error <against> bytes".into(),
            x_name: "MB".into(),
            x_unit: " MB",
            y_name: "error".into(),
            y_unit: "%",
            series: vec![Series {
                name: "512 rays".into(),
                color: "#1f77b4",
                points: vec![point(10.0, 12.0), point(40.0, 6.0)],
            }],
        };
        let svg = svg("t & u", "c", &[panel]);
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert!(svg.contains("error &lt;against&gt; bytes") && svg.contains("t &amp; u"));
        assert_eq!(
            svg.matches("<circle").count(),
            3,
            "two points and a legend mark"
        );
    }
}
