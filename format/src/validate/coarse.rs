//! Validation of the coarse bricks ([`crate::coarse`]).

use super::finite;
use crate::asset::Asset;
use crate::coarse::MAX_LEVEL;
use crate::error::FormatError;

/// None at all; or moments for every brick, each finite with a positive weight, and coarse
/// bricks whose runs of children tile the children in order, each of at least two existing
/// bricks, at a level in 1..=[`MAX_LEVEL`], with finite constants and a positive weight.
pub(super) fn coarse_bricks(asset: &Asset) -> Result<(), FormatError> {
    let c = &asset.coarse;
    if c.bricks.is_empty() {
        if !c.children.is_empty() || !c.moments.is_empty() {
            return Err(FormatError::invalid(
                "coarse",
                0,
                format!(
                    "no coarse bricks but {} children and {} moments",
                    c.children.len(),
                    c.moments.len()
                ),
            ));
        }
        return Ok(());
    }
    super::count("coarse.moments", c.moments.len(), asset.bricks.len())?;
    for (i, m) in c.moments.iter().enumerate() {
        finite("coarse.moments", i, "moment", &m.moment)?;
        if !(m.weight.is_finite() && m.weight > 0.0) {
            return Err(FormatError::invalid(
                "coarse.moments",
                i,
                format!("weight {}", m.weight),
            ));
        }
    }
    let bricks = asset.bricks.len();
    let mut next = 0u64;
    for (i, b) in c.bricks.iter().enumerate() {
        let invalid = |what: String| Err(FormatError::invalid("coarse", i, what));
        if u64::from(b.first_child) != next {
            return invalid(format!("first_child {} (expected {next})", b.first_child));
        }
        if b.child_count < 2 {
            return invalid(format!("{} children (at least 2)", b.child_count));
        }
        next += u64::from(b.child_count);
        if next > c.children.len() as u64 {
            return invalid(format!(
                "children {}..{next} past the {} listed",
                b.first_child,
                c.children.len()
            ));
        }
        if !(1..=MAX_LEVEL).contains(&b.level) {
            return invalid(format!("level {} outside 1..={MAX_LEVEL}", b.level));
        }
        if !(b.weight.is_finite() && b.weight > 0.0) {
            return invalid(format!("weight {}", b.weight));
        }
        finite("coarse", i, "centroid", &b.centroid)?;
        finite("coarse", i, "inverse", &b.inverse)?;
        let run = &c.children[b.first_child as usize..next as usize];
        if let Some(&child) = run.iter().find(|&&child| child as usize >= bricks) {
            return invalid(format!(
                "child brick {child} out of range (bricks: {bricks})"
            ));
        }
    }
    if next != c.children.len() as u64 {
        return Err(FormatError::Count {
            section: "coarse.children",
            found: c.children.len(),
            expected: next as usize,
        });
    }
    Ok(())
}
