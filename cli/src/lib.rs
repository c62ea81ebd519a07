//! What the `prt` and `prt-bench` binaries share: the values of options several of their
//! commands take ([`options`]) and the process around a command ([`process`]: the allocator's
//! policy, signals, one-line errors, the panic hook: [`panics`]). Not an engine API: engines use prt-format, prt-shaders and
//! prt-runtime.

pub mod options;
pub mod panics;
pub mod process;
mod signals;
