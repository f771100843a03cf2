//! Solid mechanics for femu.
