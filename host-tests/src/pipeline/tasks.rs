//! The firmware's task graph on the host: the same receivers, [`Core`] and status
//! receivers as [`super::Pipeline`], but split into async tasks that talk over
//! `embassy-sync` channels, as the firmware's tasks do (`firmware/channels.rs`,
//! README "Tasks and executors"), on a simulated clock.
//!
//! | task | firmware counterpart | does |
//! |---|---|---|
//! | `dma` (the bench) | DMA + interrupts | hands each buffer over at its time ([`SimClock`]) on `RAW_INPUT` / `RAW_STATUS` |
//! | `line_in` | `line::xy2_in` / `xy3_in` | `RAW_INPUT` -> controller-side receiver -> `EVENTS` |
//! | `status_in` | `status::backchannel` (rx), `status_level_in`, `hans_status_in` | `RAW_STATUS` -> head status receiver -> `HEAD_STATUS` |
//! | `bridge` | `line::bridge_wave_out`, `hans_out`, `status::backchannel` (tx), `status_level_out` | `EVENTS` / `HEAD_STATUS` / clock -> [`Core`]: `Bridge`, output slots and encoding, controller-side status |
//! | `supervisor` | `supervisor` | every 50 us: the bridge's clock must follow the system clock (else: a stall, counted; the firmware's watchdog would reset) |
//!
//! As in the firmware, the output encoding and the controller-side status run
//! inside the bridge loop (`bridge_wave_out` encodes its own batches); the tasks
//! only move buffers, every decision is in [`Core`] and `shared`.
//!
//! # Executor and time
//! The tasks are joined and driven by `embassy_futures::block_on`, a polling
//! executor: every round polls every task once, in a fixed order, so a run is
//! deterministic. Time is a [`SimClock`] owned by the bench: it moves to the next
//! buffer's time only when every channel is empty (the tasks have finished with
//! the previous one). `embassy-time`'s mock driver was not used: its clock is one
//! global, which tests running in parallel threads would share.
//!
//! [`run`] gives the same output as feeding the same buffers to a
//! [`super::Pipeline`] (tested in `tests/pipeline.rs`).

use core::cell::{Cell, RefCell};
use core::future::poll_fn;
use core::task::Poll;

use embassy_futures::block_on;
use embassy_futures::join::join4;
use embassy_futures::select::{select, select3, Either3};
use embassy_futures::yield_now;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::channel::Channel;
use shared::bridge::Config;
use shared::model::{HeadStatus, LineEvent};

use super::head_status::HeadStatusIn;
use super::input::Input;
use super::stimulus::Timed;
use super::{Core, Options, PipelineError};

/// Queue depths (the firmware's `RAW_INPUT` holds a few DMA halves too).
const DEPTH: usize = 4;
/// Supervisor period and the lag it tolerates, ns (the firmware: 50 ms / 250 ms,
/// scaled to the simulation's time spans).
const SUPERVISE_NS: u64 = 50_000;
const STALL_NS: u64 = 250_000;

/// The simulated time, ns. Only the bench moves it, and only forward.
#[derive(Debug, Default)]
pub struct SimClock {
    now: Cell<u64>,
}

impl SimClock {
    /// The current time, ns.
    pub fn now(&self) -> u64 {
        self.now.get()
    }

    fn advance(&self, t_ns: u64) {
        self.now.set(self.now.get().max(t_ns));
    }

    /// Resolves once the clock reads something other than `seen`. (The executor
    /// polls every task each round, so no waker is needed.)
    pub async fn changed(&self, seen: u64) {
        poll_fn(|_| {
            if self.now.get() != seen {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
        .await
    }

    /// Resolves once the clock has reached `t_ns`.
    pub async fn at(&self, t_ns: u64) {
        poll_fn(|_| {
            if self.now.get() >= t_ns {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
        .await
    }
}

/// Receiver events of one buffer chunk.
struct Events {
    t_ns: u64,
    events: Vec<LineEvent>,
}

/// What a status task publishes (the firmware's `HEAD_STATUS` watch, plus faults).
struct StatusUpdate {
    t_ns: u64,
    seen: u32,
    status: Box<HeadStatus>,
    faults: Vec<LineEvent>,
}

type Chan<T> = Channel<NoopRawMutex, T, DEPTH>;

/// What a task-graph run leaves behind.
pub struct TaskRun {
    /// The core with everything it produced (same accessors as a `Pipeline`).
    pub core: Core,
    /// Supervisor checks in which the bridge lagged the system clock.
    pub stalls: u32,
    /// Supervisor checks done.
    pub checks: u32,
}

/// Runs `items` (time-ordered; see [`super::stimulus`]) through the task graph
/// for `config`, then the clocks up to `end_ns`.
pub fn run(
    config: &Config,
    options: Options,
    items: &[Timed],
    end_ns: u64,
) -> Result<TaskRun, PipelineError> {
    let mut input = Input::new(config, &options)?;
    let mut status_in = HeadStatusIn::new(config, &options)?;
    let core = RefCell::new(Core::new(config, &options)?);
    let clock = SimClock::default();
    let raw_input: Chan<Timed> = Channel::new();
    let raw_status: Chan<Timed> = Channel::new();
    let events: Chan<Events> = Channel::new();
    let head_status: Chan<StatusUpdate> = Channel::new();
    let error: RefCell<Option<PipelineError>> = RefCell::new(None);
    let stalls = Cell::new(0u32);
    let checks = Cell::new(0u32);

    let idle = || {
        raw_input.is_empty() && raw_status.is_empty() && events.is_empty() && head_status.is_empty()
    };

    // DMA + interrupts: each buffer at its time, once the tasks are idle.
    let bench = async {
        for it in items {
            while !idle() {
                yield_now().await;
            }
            clock.advance(it.t_ns);
            let to = if it.buffers.is_status() {
                &raw_status
            } else {
                &raw_input
            };
            to.send(it.clone()).await;
        }
        while !idle() {
            yield_now().await;
        }
        clock.advance(end_ns);
        // One more round for the bridge to run its clocks to the end.
        yield_now().await;
        yield_now().await;
    };

    let line_in = async {
        loop {
            let it = raw_input.receive().await;
            let mut ev = Vec::new();
            let r = it
                .buffers
                .controller_input(|chunk| input.feed(chunk, &mut ev))
                .unwrap_or(Ok(()));
            if let Err(e) = r {
                error.borrow_mut().get_or_insert(e);
            }
            events
                .send(Events {
                    t_ns: it.t_ns,
                    events: ev,
                })
                .await;
        }
    };

    let status = async {
        loop {
            let it = raw_status.receive().await;
            let mut faults = Vec::new();
            let r = it
                .buffers
                .status_input(|chunk| status_in.feed(it.t_ns, chunk, &mut faults))
                .unwrap_or(Ok(0));
            let seen = r.unwrap_or_else(|e| {
                error.borrow_mut().get_or_insert(e);
                0
            });
            head_status
                .send(StatusUpdate {
                    t_ns: it.t_ns,
                    seen,
                    status: Box::new(status_in.status().clone()),
                    faults,
                })
                .await;
        }
    };

    let bridge = async {
        let mut seen = clock.now();
        loop {
            match select3(events.receive(), head_status.receive(), clock.changed(seen)).await {
                Either3::First(m) => core.borrow_mut().line_events(m.t_ns, &m.events),
                Either3::Second(m) => core
                    .borrow_mut()
                    .head_status(m.t_ns, m.seen, &m.status, &m.faults),
                Either3::Third(()) => {
                    seen = clock.now();
                    core.borrow_mut().run_until(seen);
                }
            }
        }
    };

    let supervisor = async {
        let mut next = SUPERVISE_NS;
        loop {
            clock.at(next).await;
            checks.set(checks.get() + 1);
            // The bridge runs after the bench in each round: give it that round.
            yield_now().await;
            if core.borrow().now_ns() + STALL_NS < clock.now() {
                stalls.set(stalls.get() + 1);
            }
            next = clock.now() + SUPERVISE_NS;
        }
    };

    block_on(select(bench, join4(line_in, status, bridge, supervisor)));
    if let Some(e) = error.into_inner() {
        return Err(e);
    }
    Ok(TaskRun {
        core: core.into_inner(),
        stalls: stalls.get(),
        checks: checks.get(),
    })
}
