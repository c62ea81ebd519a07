//! Memory plumbing shared by the stages.

pub(crate) mod chunked;
