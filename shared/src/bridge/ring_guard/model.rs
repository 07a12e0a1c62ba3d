//! A model of the guarded ring and the random walk over it, shared by the host
//! tests (`ring_guard::tests`, proptest) and the on-target runner (`cm7`, built with
//! the `vectors` feature) so both drive the guard through the same steps and check
//! the same invariants. Not part of the API: only compiled for tests or with
//! `vectors`.
//!
//! The model keeps, per ring half, what its lead ([`super::LEAD_WORDS`]) and the
//! rest hold: idle words or the words of one absolute half. A step is a boundary
//! (the DMA enters the next half), a claim while a boundary is pending, or the
//! writer's next batch (claim with a retry on [`Claim::Late`], copy, fill; the copy
//! possibly overtaken by the boundary). A broken invariant is returned as
//! [`Broken`] rather than asserted, so each runner reports it its own way
//! (`prop_assert!` on the host, a panic on the target).

use super::{Actions, Claim, Fill, RingGuard};

/// Words in a ring half (the model's unit of DMA progress).
pub const HALF: usize = 1000;
/// Words a copy needs at most (the claim's margin).
pub const MARGIN: usize = 100;

/// What a part of a ring half holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Words {
    /// The idle word.
    Idle,
    /// The words of this absolute half.
    Of(u64),
}

/// The model ring: per ring half its lead and the rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ring {
    /// The first [`super::LEAD_WORDS`] of each ring half.
    pub lead: [Words; 2],
    /// The rest of each ring half.
    pub body: [Words; 2],
}

impl Default for Ring {
    fn default() -> Self {
        Self::new()
    }
}

impl Ring {
    /// The idle pre-fill.
    pub const fn new() -> Self {
        Self {
            lead: [Words::Idle; 2],
            body: [Words::Idle; 2],
        }
    }

    /// Carries out the guard's actions of a boundary.
    pub fn apply(&mut self, a: &Actions) {
        if let Some(s) = a.blank_lead {
            self.lead[s] = Words::Idle;
        }
        if let Some(s) = a.blank_rest {
            self.body[s] = Words::Idle;
        }
        if let Some(s) = a.blank_all {
            self.blank(s);
        }
    }

    /// The writer's copy of half `n`.
    pub fn write(&mut self, n: u64) {
        let s = (n % 2) as usize;
        self.lead[s] = Words::Of(n);
        self.body[s] = Words::Of(n);
    }

    /// Sets the whole ring half `s` (0 or 1) to idle.
    pub fn blank(&mut self, s: usize) {
        self.lead[s] = Words::Idle;
        self.body[s] = Words::Idle;
    }

    /// The DMA enters the next half: it plays the lead during the guard's latency,
    /// then the rest after the guard acted. Unchecked: see [`Walk::boundary`].
    pub fn boundary(&mut self, g: &mut RingGuard) -> Played {
        let half = g.playing() + 1;
        let s = (half % 2) as usize;
        let lead = self.lead[s];
        let actions = g.boundary();
        self.apply(&actions);
        Played {
            half,
            lead,
            body: self.body[s],
            actions,
        }
    }
}

/// What the DMA played at a boundary, and the guard's actions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Played {
    /// The absolute half the DMA entered.
    pub half: u64,
    /// What its lead played (before the guard acted).
    pub lead: Words,
    /// What the rest played (after the guard acted).
    pub body: Words,
    /// The guard's actions.
    pub actions: Actions,
}

impl Played {
    /// The half played wholly its own words.
    pub fn own(&self) -> bool {
        self.lead == Words::Of(self.half) && self.body == Words::Of(self.half)
    }
}

/// One step of a walk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The writer writes its next batch; the copy is overtaken by a boundary
    /// (`torn`) or not; `left` is where the DMA is in its half (words still to play).
    Write {
        /// Words the DMA has still to play in its half.
        left: usize,
        /// The DMA enters the claimed half mid-copy.
        torn: bool,
    },
    /// The DMA crosses a boundary (the writer does nothing).
    Boundary,
    /// A claim while the boundary is pending (DMA already in the other ring half).
    Pending,
}

/// A broken invariant of the walk: the first one found ends it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Broken {
    /// The guard plays `playing` after a boundary into `half`.
    Playing {
        /// The half the DMA entered.
        half: u64,
        /// The guard's [`RingGuard::playing`] after it.
        playing: u64,
    },
    /// The DMA played another half's words in `half` (the ring guard's purpose).
    Stale {
        /// The half played.
        half: u64,
        /// What its lead played.
        lead: Words,
        /// What its rest played.
        body: Words,
    },
    /// A half from 2 on not wholly its own played with the gate on.
    GateOn {
        /// The half played.
        half: u64,
    },
    /// The gate went off in a half that played its own words.
    GateOff {
        /// The half played.
        half: u64,
    },
    /// [`RingGuard::missed`] is not the count of boundaries that turned the gate off.
    Missed {
        /// The half played last.
        half: u64,
        /// Gate-off boundaries the walk counted.
        counted: u32,
        /// What the guard says.
        guard: u32,
    },
    /// A claim answered other than it must: a pending boundary not [`Claim::Wait`],
    /// or [`Claim::Late`] not beyond the half asked for and the one playing.
    Claim {
        /// The half asked for.
        half: u64,
        /// The half the DMA plays.
        playing: u64,
        /// The answer.
        got: Claim,
    },
    /// A half granted that is not the one after the playing one, or with less
    /// than the margin left.
    Granted {
        /// The half granted.
        half: u64,
        /// The half the DMA plays.
        playing: u64,
        /// The words left in the playing half.
        left: usize,
    },
    /// A fill answered `got`: torn without the DMA in the half, or done with it.
    Fill {
        /// The half filled.
        half: u64,
        /// The answer.
        got: Fill,
    },
    /// A written half did not play as written at its boundary, or a torn copy's
    /// boundary went into another half or left the gate on.
    Written {
        /// The half written.
        half: u64,
        /// What the boundary played.
        played: Played,
    },
}

/// The guard, the model ring and the writer's next half, walked by [`Step`]s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Walk {
    /// The guard under test.
    pub guard: RingGuard,
    /// What the ring holds.
    pub ring: Ring,
    /// The half the writer writes next.
    pub next: u64,
    /// Boundaries that turned the gate off so far.
    misses: u32,
}

impl Default for Walk {
    fn default() -> Self {
        Self::new()
    }
}

impl Walk {
    /// At the start of a run: the DMA plays half 0 of the idle pre-fill, the writer
    /// writes half 2 first.
    pub const fn new() -> Self {
        Self {
            guard: RingGuard::new(),
            ring: Ring::new(),
            next: 2,
            misses: 0,
        }
    }

    /// One step.
    pub fn step(&mut self, s: Step) -> Result<(), Broken> {
        match s {
            Step::Boundary => self.boundary().map(drop),
            Step::Pending => self.pending(),
            Step::Write { left, torn } => self.write(left, torn).map(drop),
        }
    }

    /// The DMA enters the next half. Checks that it plays the half's own words or
    /// idle (lead and rest), that the gate goes off in every half from 2 on that
    /// is not wholly its own and only in those, and that the guard counts every
    /// gate-off boundary as a miss.
    pub fn boundary(&mut self) -> Result<Played, Broken> {
        let p = self.ring.boundary(&mut self.guard);
        let half = p.half;
        if self.guard.playing() != half {
            return Err(Broken::Playing {
                half,
                playing: self.guard.playing(),
            });
        }
        let fresh_or_idle = |w: Words| w == Words::Idle || w == Words::Of(half);
        if !fresh_or_idle(p.lead) || !fresh_or_idle(p.body) {
            return Err(Broken::Stale {
                half,
                lead: p.lead,
                body: p.body,
            });
        }
        let own = p.own();
        if half >= 2 && !own && !p.actions.gate_off {
            return Err(Broken::GateOn { half });
        }
        if p.actions.gate_off {
            if own {
                return Err(Broken::GateOff { half });
            }
            self.misses = self.misses.wrapping_add(1);
        }
        if self.guard.missed() != self.misses {
            return Err(Broken::Missed {
                half,
                counted: self.misses,
                guard: self.guard.missed(),
            });
        }
        Ok(p)
    }

    /// A claim of the writer's next half with the DMA already in the other ring
    /// half (the boundary not handled yet): it must wait.
    pub fn pending(&mut self) -> Result<(), Broken> {
        let other = ((self.guard.playing() + 1) % 2) as usize;
        match self.guard.claim(self.next, other, HALF, MARGIN) {
            Claim::Wait => Ok(()),
            got => Err(Broken::Claim {
                half: self.next,
                playing: self.guard.playing(),
                got,
            }),
        }
    }

    /// The writer's step with the DMA `left` words before the end of its half: it
    /// claims its next half, once more with the half a [`Claim::Late`] names (the
    /// batch dropped), and if granted copies and fills it. A `torn` copy is
    /// overtaken by the boundary into the half (checked as a miss), the fill is
    /// [`Fill::Torn`] and the writer blanks the whole half again; otherwise the
    /// fill is [`Fill::Done`] and the next boundary plays the half as written.
    /// Returns whether the claim was granted.
    pub fn write(&mut self, left: usize, torn: bool) -> Result<bool, Broken> {
        let dma = (self.guard.playing() % 2) as usize;
        let mut granted = false;
        for _ in 0..2 {
            match self.guard.claim(self.next, dma, left, MARGIN) {
                Claim::Granted => {
                    granted = true;
                    break;
                }
                Claim::Late { next } => {
                    if next <= self.next || next <= self.guard.playing() {
                        return Err(Broken::Claim {
                            half: self.next,
                            playing: self.guard.playing(),
                            got: Claim::Late { next },
                        });
                    }
                    self.next = next;
                }
                Claim::Wait => break,
            }
        }
        if !granted {
            return Ok(false);
        }
        let half = self.next;
        if half != self.guard.playing() + 1 || left < MARGIN {
            return Err(Broken::Granted {
                half,
                playing: self.guard.playing(),
                left,
            });
        }
        if torn {
            // The DMA enters the claimed half mid-copy.
            let played = self.boundary()?;
            if played.half != half || !played.actions.gate_off {
                return Err(Broken::Written { half, played });
            }
            self.ring.write(half);
            match self.guard.fill(half) {
                // The writer blanks the whole half again (behind the DMA harmless,
                // in front of it what it has not played yet).
                Fill::Torn => self.ring.blank((half % 2) as usize),
                got => return Err(Broken::Fill { half, got }),
            }
        } else {
            self.ring.write(half);
            match self.guard.fill(half) {
                Fill::Done => {}
                got => return Err(Broken::Fill { half, got }),
            }
            // Written halves play as written at their boundary.
            let played = self.boundary()?;
            if played.half != half || !played.own() {
                return Err(Broken::Written { half, played });
            }
        }
        self.next += 1;
        Ok(true)
    }
}
