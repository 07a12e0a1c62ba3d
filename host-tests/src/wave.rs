//! Protocol-agnostic waveform model: named single-bit signals on a picosecond time axis.
//!
//! A [`Signal`] is an initial level plus a strictly time-ordered list of level *changes*
//! (every stored change really flips the level, so the list is also the list of edges).
//! A [`Waveform`] is a set of uniquely named signals. Times are `u64` picoseconds from the
//! start of the capture/simulation (enough for ~213 days).
//!
//! Level semantics: a change at time `t` is in effect *at* `t`, so [`Signal::level_at`]
//! at exactly an edge's time returns the new level. Samplers built on this (see
//! [`crate::line`]) therefore model an ideal receiver with zero setup/hold time.

use std::fmt;

/// Time in picoseconds.
pub type Ps = u64;

/// Picoseconds per second, for converting rates and periods.
pub const PS_PER_S: f64 = 1e12;

/// One edge of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    /// Time of the edge in picoseconds.
    pub time: Ps,
    /// `true` for a rising (low -> high) edge, `false` for a falling one.
    pub rising: bool,
}

/// Errors building a waveform.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WaveError {
    /// A change was pushed earlier than the signal's last change.
    TimeBackwards {
        /// Signal name.
        signal: String,
        /// Time of the rejected change.
        time: Ps,
        /// Time of the signal's last change.
        last: Ps,
    },
    /// A signal with this name is already in the waveform.
    DuplicateSignal {
        /// The duplicated name.
        name: String,
    },
}

impl fmt::Display for WaveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TimeBackwards { signal, time, last } => write!(
                f,
                "signal `{signal}`: change at {time} ps is earlier than the previous change at {last} ps"
            ),
            Self::DuplicateSignal { name } => {
                write!(f, "a signal named `{name}` already exists in the waveform")
            }
        }
    }
}

impl std::error::Error for WaveError {}

/// A named single-bit signal: initial level plus time-ordered level changes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Signal {
    name: String,
    initial: bool,
    /// Strictly increasing times; each entry flips the level (invariant kept by `push`).
    changes: Vec<(Ps, bool)>,
}

impl Signal {
    /// A signal that stays at `initial` forever.
    pub fn new(name: impl Into<String>, initial: bool) -> Self {
        Self {
            name: name.into(),
            initial,
            changes: Vec::new(),
        }
    }

    /// Builds a signal from `(time, level)` pairs that must be in non-decreasing time
    /// order. Pairs that do not change the level are dropped; at equal times the last one
    /// wins.
    pub fn from_changes(
        name: impl Into<String>,
        initial: bool,
        changes: impl IntoIterator<Item = (Ps, bool)>,
    ) -> Result<Self, WaveError> {
        let mut s = Self::new(name, initial);
        for (t, level) in changes {
            s.push(t, level)?;
        }
        Ok(s)
    }

    /// Sets the level from `time` on. `time` must not be earlier than the last change;
    /// a change at the same time as the last one replaces it (and cancels it if the
    /// level goes back to what it was before). Non-changes are ignored. Time 0 is the
    /// start of the time axis, so a change at 0 sets the initial level (this keeps the
    /// representation unique: VCD cannot tell the two apart either).
    pub fn push(&mut self, time: Ps, level: bool) -> Result<(), WaveError> {
        if time == 0 && self.changes.is_empty() {
            self.initial = level;
            return Ok(());
        }
        if let Some(&(last, _)) = self.changes.last() {
            if time < last {
                return Err(WaveError::TimeBackwards {
                    signal: self.name.clone(),
                    time,
                    last,
                });
            }
            if time == last {
                self.changes.pop();
            }
        }
        if self.final_level() != level {
            self.changes.push((time, level));
        }
        Ok(())
    }

    /// The signal's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Renames the signal (used when mapping capture names to roles).
    pub fn set_name(&mut self, name: impl Into<String>) {
        self.name = name.into();
    }

    /// Level at time 0, before the first change.
    pub fn initial(&self) -> bool {
        self.initial
    }

    /// Level after the last change.
    pub fn final_level(&self) -> bool {
        self.changes.last().map_or(self.initial, |&(_, l)| l)
    }

    /// The level changes as `(time, new level)`, strictly increasing in time.
    pub fn changes(&self) -> &[(Ps, bool)] {
        &self.changes
    }

    /// Time of the last change (0 for a constant signal).
    pub fn end_time(&self) -> Ps {
        self.changes.last().map_or(0, |&(t, _)| t)
    }

    /// Level at time `t` (changes at exactly `t` are already in effect).
    pub fn level_at(&self, t: Ps) -> bool {
        let n = self.changes.partition_point(|&(ct, _)| ct <= t);
        match n.checked_sub(1).and_then(|i| self.changes.get(i)) {
            Some(&(_, level)) => level,
            None => self.initial,
        }
    }

    /// All edges in time order.
    pub fn edges(&self) -> impl Iterator<Item = Edge> + '_ {
        self.changes
            .iter()
            .map(|&(time, rising)| Edge { time, rising })
    }

    /// Times of the rising edges.
    pub fn rising_edges(&self) -> impl Iterator<Item = Ps> + '_ {
        self.edges().filter(|e| e.rising).map(|e| e.time)
    }

    /// Times of the falling edges.
    pub fn falling_edges(&self) -> impl Iterator<Item = Ps> + '_ {
        self.edges().filter(|e| !e.rising).map(|e| e.time)
    }
}

/// Builds a signal by appending levels held for durations, e.g. for hand-made test
/// patterns: `SignalBuilder::new("D", false).hold(true, 80_000).hold(false, 80_000)`.
#[derive(Debug, Clone)]
pub struct SignalBuilder {
    signal: Signal,
    now: Ps,
}

impl SignalBuilder {
    /// Starts at time 0 with the given initial level.
    pub fn new(name: impl Into<String>, initial: bool) -> Self {
        Self {
            signal: Signal::new(name, initial),
            now: 0,
        }
    }

    /// Drives `level` from the current time for `duration` picoseconds.
    #[must_use]
    pub fn hold(mut self, level: bool, duration: Ps) -> Self {
        // Times only grow here, so `push` cannot fail.
        let _ = self.signal.push(self.now, level);
        self.now = self.now.saturating_add(duration);
        self
    }

    /// The current time (end of the last `hold`).
    pub fn now(&self) -> Ps {
        self.now
    }

    /// Finishes the signal.
    pub fn build(self) -> Signal {
        self.signal
    }
}

/// A set of uniquely named signals, in insertion order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Waveform {
    signals: Vec<Signal>,
}

impl Waveform {
    /// An empty waveform.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a signal; its name must be new.
    pub fn add(&mut self, signal: Signal) -> Result<(), WaveError> {
        if self.get(signal.name()).is_some() {
            return Err(WaveError::DuplicateSignal {
                name: signal.name().to_owned(),
            });
        }
        self.signals.push(signal);
        Ok(())
    }

    /// Adds a signal, replacing any signal of the same name.
    pub fn insert(&mut self, signal: Signal) {
        match self.signals.iter_mut().find(|s| s.name() == signal.name()) {
            Some(slot) => *slot = signal,
            None => self.signals.push(signal),
        }
    }

    /// The signal named `name`.
    pub fn get(&self, name: &str) -> Option<&Signal> {
        self.signals.iter().find(|s| s.name() == name)
    }

    /// The signal named `name`, mutably.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut Signal> {
        self.signals.iter_mut().find(|s| s.name() == name)
    }

    /// All signals in insertion order.
    pub fn signals(&self) -> &[Signal] {
        &self.signals
    }

    /// All signals, mutably.
    pub fn signals_mut(&mut self) -> &mut [Signal] {
        &mut self.signals
    }

    /// Names of all signals.
    pub fn names(&self) -> Vec<String> {
        self.signals.iter().map(|s| s.name().to_owned()).collect()
    }

    /// Time of the latest change of any signal.
    pub fn end_time(&self) -> Ps {
        self.signals.iter().map(Signal::end_time).max().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_normalises_and_queries() {
        let mut s = Signal::new("a", false);
        s.push(0, false).unwrap(); // no change
        s.push(10, true).unwrap();
        s.push(10, true).unwrap(); // same
        s.push(20, false).unwrap();
        s.push(20, true).unwrap(); // replaces and cancels the fall at 20
        s.push(30, false).unwrap();
        assert_eq!(s.changes(), &[(10, true), (30, false)]);
        assert!(!s.level_at(9));
        assert!(s.level_at(10));
        assert!(s.level_at(29));
        assert!(!s.level_at(30));
        assert_eq!(s.rising_edges().collect::<Vec<_>>(), vec![10]);
        assert_eq!(s.falling_edges().collect::<Vec<_>>(), vec![30]);
        assert!(matches!(
            s.push(5, true),
            Err(WaveError::TimeBackwards {
                time: 5,
                last: 30,
                ..
            })
        ));
    }

    #[test]
    fn waveform_rejects_duplicates() {
        let mut w = Waveform::new();
        w.add(Signal::new("x", false)).unwrap();
        let e = w.add(Signal::new("x", true)).unwrap_err();
        assert!(e.to_string().contains("`x`"));
        let b = SignalBuilder::new("b", false)
            .hold(true, 5)
            .hold(false, 5)
            .build();
        assert!(b.initial());
        assert_eq!(b.changes(), &[(5, false)]);
    }
}
