//! Earlier sweeps read back (`--previous`): the setting, bake time and mean error of every row
//! of an `accuracy.md` this bench wrote, so that the new front is drawn beside the old.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::{setting, Point};

/// Every setting of earlier sweeps' tables (`accuracy.md` as this bench writes it) with its least
/// bake time over the files.
pub(super) fn read_previous(paths: &[PathBuf]) -> Result<Vec<Point>> {
    let mut best: BTreeMap<String, Point> = BTreeMap::new();
    for path in paths {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the previous sweep {}", path.display()))?;
        for point in parse_table(&text, path)? {
            match best.get_mut(&point.setting) {
                Some(p) if p.bake_ms <= point.bake_ms => {}
                _ => {
                    best.insert(point.setting.clone(), point);
                }
            }
        }
    }
    Ok(best.into_values().collect())
}

/// The cells of a Markdown table row.
fn cells(line: &str) -> Vec<String> {
    line.trim()
        .trim_matches('|')
        .split('|')
        .map(|c| c.trim().to_owned())
        .collect()
}

/// The columns of a previous sweep's table that [`parse_table`] reads, by their index.
struct Columns {
    rays: usize,
    merge: usize,
    precision: usize,
    encoding: usize,
    bake: usize,
    error: usize,
}

/// The settings of the first table in `text` (columns found by their headers).
pub(super) fn parse_table(text: &str, path: &Path) -> Result<Vec<Point>> {
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .skip_while(|(_, l)| !l.starts_with('|'))
        .take_while(|(_, l)| l.starts_with('|'));
    let Some((header_line, header)) = lines.next() else {
        bail!("{}: no table (a line starting with '|')", path.display());
    };
    let at = |line: usize| format!("{} line {line}", path.display());
    let header = cells(header);
    let column = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .with_context(|| format!("{}: no column '{name}' in the header", at(header_line)))
    };
    let columns = Columns {
        rays: column("rays")?,
        merge: column("brick cells")?,
        precision: column("transfer")?,
        encoding: column("encoding")?,
        bake: column("bake ms")?,
        error: column("mean err")?,
    };
    let separator = |c: &String| !c.is_empty() && c.trim_matches(':').chars().all(|x| x == '-');
    match lines.next() {
        Some((_, l)) if cells(l).iter().all(separator) => {}
        Some((n, l)) => bail!("{}: '{l}' is not the header's separator row", at(n)),
        None => bail!("{}: a header and no rows", at(header_line)),
    }
    let points = lines
        .map(|(n, line)| point_of(&cells(line), &header, &columns, &at(n)))
        .collect::<Result<Vec<_>>>()?;
    if points.is_empty() {
        bail!("{}: a header and no rows", at(header_line));
    }
    Ok(points)
}

/// The setting in the cells `c` of a table row (`at` names its file and line).
fn point_of(c: &[String], header: &[String], columns: &Columns, at: &str) -> Result<Point> {
    let get = |i: usize| {
        c.get(i).map(String::as_str).with_context(|| {
            let (have, want) = (c.len(), header.len());
            format!(
                "{at}: no cell for column '{}' ({have} cells, the header has {want})",
                header[i]
            )
        })
    };
    let bad = |i: usize, what: &str| {
        anyhow::anyhow!("{at}: column '{}' is '{}', not {what}", header[i], c[i])
    };
    let number = |i: usize| -> Result<f64> {
        match get(i)?.trim_end_matches('%').parse::<f64>() {
            Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
            _ => Err(bad(i, "a non-negative number")),
        }
    };
    let ray_count = get(columns.rays)?
        .parse::<u32>()
        .map_err(|_| bad(columns.rays, "a ray count"))?;
    let (merge, encoding) = (get(columns.merge)?, get(columns.encoding)?);
    Ok(Point {
        setting: setting(
            &ray_count.to_string(),
            merge,
            get(columns.precision)?,
            encoding,
        ),
        merge: merge.to_owned(),
        flat: encoding.ends_with("flat brick"),
        bake_ms: number(columns.bake)?,
        error: number(columns.error)?,
    })
}
