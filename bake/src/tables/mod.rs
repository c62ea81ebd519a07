//! Factor tables: each probe's (brick, ray count, SH9 transfer) rows, and where they wait,
//! in memory or in a temporary file, until the bricks are numbered.

pub mod encode;
pub mod factors;
pub mod row_store;
