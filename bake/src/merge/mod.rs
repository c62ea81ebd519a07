//! Merging ray hits into bricks and surfels as they arrive: [`key`] says which brick a hit
//! belongs to, `index` finds that brick, [`fold`] merges the hit into its cell's surfels and
//! numbers the bricks at the end, keeping apart the hits [`sides`] finds across a wall in their
//! cell; [`split`] splits a brick where a wall stands on it;
//! [`coarse`] makes the coarse bricks of far hits, split where [`links`] finds a wall.

pub mod coarse;
pub mod fold;
pub(crate) mod index;
pub mod key;
pub mod links;
pub mod sides;
pub mod snap;
pub mod split;
