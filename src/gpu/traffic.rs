//! Bytes a dispatch reads and writes in device memory ([`Traffic`]), as the stages that
//! know their access patterns count them: each element a shader loads or stores counted
//! once (caches, re-reads and partial cache lines are not modelled), so a stage's
//! traffic divided by its time is the bandwidth it reached at least.

use std::ops::{Add, AddAssign};

/// Bytes read and written in device memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Traffic {
    /// Bytes loaded.
    pub read: u64,
    /// Bytes stored.
    pub written: u64,
}

impl Traffic {
    /// `read` bytes loaded and `written` stored.
    pub const fn new(read: u64, written: u64) -> Self {
        Traffic { read, written }
    }

    /// Read plus written.
    pub const fn total(self) -> u64 {
        self.read + self.written
    }

    /// `self` `times` over.
    pub const fn times(self, times: u64) -> Self {
        Traffic::new(self.read * times, self.written * times)
    }
}

impl Add for Traffic {
    type Output = Traffic;
    fn add(self, other: Traffic) -> Traffic {
        Traffic::new(self.read + other.read, self.written + other.written)
    }
}

impl AddAssign for Traffic {
    fn add_assign(&mut self, other: Traffic) {
        *self = *self + other;
    }
}

impl std::iter::Sum for Traffic {
    fn sum<I: Iterator<Item = Traffic>>(iter: I) -> Traffic {
        iter.fold(Traffic::default(), Add::add)
    }
}
