//! Merging ray hits into bricks and surfels: the index from brick key to brick, and the fold
//! that merges hits as they arrive.

pub mod fold;
mod index;
