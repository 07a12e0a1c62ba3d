//! The firmware's task graph on the host: the same receivers, [`Core`] and status
//! receivers as [`super::Pipeline`], but split into async tasks on an
//! embassy-executor that talk over `embassy-sync` channels, as the firmware's
//! tasks do (`firmware/channels.rs`, README "Tasks and executors"), on a
//! simulated clock.
//!
//! | task | firmware counterpart | does |
//! |---|---|---|
//! | the bench (not a task) | DMA + interrupts | hands each buffer over at its time on `RAW_INPUT` / `RAW_STATUS`; moves the [`SimClock`] |
//! | `line_in` | `line::xy2_in` / `xy3_in` | `RAW_INPUT` -> controller-side receiver -> `EVENTS` |
//! | `status_in` | `status::backchannel` (rx), `status_level_in`, `hans_status_in` | `RAW_STATUS` -> head status receiver -> `HEAD_STATUS` |
//! | `bridge` | `line::bridge_wave_out`, `hans_out`, `status::backchannel` (tx), `status_level_out` | `EVENTS` / `HEAD_STATUS` / clock -> [`Core`]: `Bridge`, output slots and encoding, controller-side status |
//! | `supervisor` | `supervisor` | every 50 us (a timer): the bridge's clock must follow the system clock (else: a stall, counted; the firmware's watchdog would reset) |
//!
//! As in the firmware, the output encoding and the controller-side status run
//! inside the bridge loop (`bridge_wave_out` encodes its own batches); the tasks
//! only move buffers, every decision is in [`Core`] and `shared`.
//!
//! # Executor and time
//! Each run has its own embassy-executor (`exec`: the raw executor every
//! embassy platform executor wraps, polled by the bench) and its own
//! [`SimClock`], so tests can run in parallel threads. A task runs only when
//! something wakes it: a channel (embassy-sync's wakers) or the clock (its own
//! wakers). The bench repeats: poll the executor until no task is ready (every
//! task waits for a wake), check that every channel is empty (otherwise a task
//! missed its wake or is blocked: [`TaskError::Stuck`]), then move the clock to
//! the next due timer or the next buffer's time, whichever is first, and hand
//! over that buffer. After `end_ns` the tasks are told to stop; each returns, and
//! a task that does not is an error ([`TaskError::NotStopped`]). Everything runs
//! on the calling thread and the executor's order is fixed, so a run is
//! deterministic.
//!
//! [`run`] gives the same output as feeding the same buffers to a
//! [`super::Pipeline`] (tested in `tests/pipeline.rs`).

mod clock;
// The raw executor's `poll` and the pender it calls are `unsafe` by embassy's
// API; they are confined to this module.
#[allow(unsafe_code)]
mod exec;

use core::cell::{Cell, RefCell};
use core::fmt;
use core::future::{poll_fn, Future};
use core::task::Poll;
use std::rc::Rc;

use embassy_executor::SpawnError;
use embassy_futures::select::{select, select3, Either3};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::channel::Channel;
use shared::bridge::Config;
use shared::model::{HeadStatus, LineEvent};

pub use clock::SimClock;
use clock::Wakers;
use exec::SimExecutor;

use super::head_status::HeadStatusIn;
use super::input::Input;
use super::stimulus::Timed;
use super::{Core, Options, PipelineError};

/// Queue depths (the firmware's `RAW_INPUT` holds a few DMA halves too).
const DEPTH: usize = 4;
/// Supervisor period and the lag it tolerates, ns (the firmware: 50 ms / 250 ms,
/// scaled to the simulation's time spans).
pub const SUPERVISE_NS: u64 = 50_000;
const STALL_NS: u64 = 250_000;
/// Executor polls allowed for the tasks to go idle after one step of the bench.
/// One step needs a handful (a buffer passes three tasks); more means tasks keep
/// waking each other.
const MAX_POLLS: u32 = 10_000;

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

/// Why a task-graph run failed.
#[derive(Debug)]
pub enum TaskError {
    /// The pipeline refused its set-up or a buffer.
    Pipeline(PipelineError),
    /// The executor refused a task.
    Spawn(SpawnError),
    /// Every task waited for a wake while `queue` still held a message: its
    /// receiver was not woken, or is blocked elsewhere.
    Stuck {
        /// Simulated time, ns.
        t_ns: u64,
        /// The channel (the firmware's name).
        queue: &'static str,
    },
    /// The tasks kept waking each other for 10 000 executor polls without going idle.
    Busy {
        /// Simulated time, ns.
        t_ns: u64,
    },
    /// Tasks still running after they were told to stop.
    NotStopped {
        /// How many.
        tasks: usize,
    },
}

impl fmt::Display for TaskError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Pipeline(e) => write!(f, "pipeline: {e}"),
            Self::Spawn(e) => write!(f, "cannot spawn a task: {e}"),
            Self::Stuck { t_ns, queue } => write!(
                f,
                "at {t_ns} ns every task waits but {queue} is not empty (a lost wake or a blocked task)"
            ),
            Self::Busy { t_ns } => write!(
                f,
                "at {t_ns} ns the tasks were still ready after {MAX_POLLS} executor polls"
            ),
            Self::NotStopped { tasks } => {
                write!(f, "{tasks} task(s) still running after the stop")
            }
        }
    }
}

impl std::error::Error for TaskError {}

impl From<PipelineError> for TaskError {
    fn from(e: PipelineError) -> Self {
        Self::Pipeline(e)
    }
}

/// What a task-graph run leaves behind.
pub struct TaskRun {
    /// The core with everything it produced (same accessors as a `Pipeline`).
    pub core: Core,
    /// Supervisor checks in which the bridge lagged the system clock.
    pub stalls: u32,
    /// Supervisor checks done.
    pub checks: u32,
    /// Executor polls over the run.
    pub polls: u64,
}

/// What the tasks share (the firmware's statics in `firmware/channels.rs`).
struct Graph {
    clock: SimClock,
    core: RefCell<Core>,
    raw_input: Chan<Timed>,
    raw_status: Chan<Timed>,
    events: Chan<Events>,
    head_status: Chan<StatusUpdate>,
    /// The first receiver error (the run goes on, as the firmware's would).
    error: RefCell<Option<PipelineError>>,
    stalls: Cell<u32>,
    checks: Cell<u32>,
    stop: Cell<bool>,
    on_stop: Wakers,
}

impl Graph {
    /// The first channel still holding a message, by its firmware name.
    fn busy_queue(&self) -> Option<&'static str> {
        [
            ("RAW_INPUT", self.raw_input.is_empty()),
            ("RAW_STATUS", self.raw_status.is_empty()),
            ("EVENTS", self.events.is_empty()),
            ("HEAD_STATUS", self.head_status.is_empty()),
        ]
        .into_iter()
        .find_map(|(name, empty)| (!empty).then_some(name))
    }

    fn note_error(&self, e: PipelineError) {
        self.error.borrow_mut().get_or_insert(e);
    }

    /// Runs `body` until the bench stops the tasks. The stop is polled first, so
    /// a task woken only by the stop does no more work (a supervisor that missed
    /// its timer's wakes does not catch up on its checks here).
    async fn until_stopped(&self, body: impl Future<Output = ()>) {
        let stopped = poll_fn(|cx| {
            if self.stop.get() {
                Poll::Ready(())
            } else {
                self.on_stop.register(cx.waker());
                Poll::Pending
            }
        });
        select(stopped, body).await;
    }
}

/// `input` is boxed so the task's storage, which outlives the run, stays small.
async fn line_in(g: &Graph, mut input: Box<Input>) {
    loop {
        let it = g.raw_input.receive().await;
        let mut events = Vec::new();
        let fed = it
            .buffers
            .controller_input(|chunk| input.feed(it.t_ns, chunk, &mut events));
        if let Some(Err(e)) = fed {
            g.note_error(e);
        }
        g.events
            .send(Events {
                t_ns: it.t_ns,
                events,
            })
            .await;
    }
}

/// Boxed, as in [`line_in`].
async fn status_in(g: &Graph, mut status_in: Box<HeadStatusIn>) {
    loop {
        let it = g.raw_status.receive().await;
        let mut faults = Vec::new();
        let fed = it
            .buffers
            .status_input(|chunk| status_in.feed(it.t_ns, chunk, &mut faults));
        let seen = match fed {
            Some(Ok(seen)) => seen,
            Some(Err(e)) => {
                g.note_error(e);
                0
            }
            None => 0,
        };
        g.head_status
            .send(StatusUpdate {
                t_ns: it.t_ns,
                seen,
                status: Box::new(status_in.status().clone()),
                faults,
            })
            .await;
    }
}

async fn bridge(g: &Graph) {
    let mut seen = g.clock.now();
    loop {
        match select3(
            g.events.receive(),
            g.head_status.receive(),
            g.clock.changed(seen),
        )
        .await
        {
            Either3::First(m) => g.core.borrow_mut().line_events(m.t_ns, &m.events),
            Either3::Second(m) => g
                .core
                .borrow_mut()
                .head_status(m.t_ns, m.seen, &m.status, &m.faults),
            Either3::Third(()) => {
                seen = g.clock.now();
                g.core.borrow_mut().run_until(seen);
            }
        }
    }
}

async fn supervisor(g: &Graph) {
    let mut next = SUPERVISE_NS;
    loop {
        g.clock.at(next).await;
        g.checks.set(g.checks.get() + 1);
        // The bench stops at every timer, so the clock moved at most one period
        // since the bridge last ran; a lag of STALL_NS means it missed wakes.
        if g.core.borrow().now_ns() + STALL_NS < g.clock.now() {
            g.stalls.set(g.stalls.get() + 1);
        }
        next += SUPERVISE_NS;
    }
}

/// The bench: drives the executor and the clock.
struct Bench<'a> {
    g: &'a Graph,
    exec: SimExecutor,
    polls: u64,
}

impl Bench<'_> {
    /// Polls until every task waits, then checks that every channel is empty.
    fn settle(&mut self) -> Result<(), TaskError> {
        let t_ns = self.g.clock.now();
        self.polls += u64::from(
            self.exec
                .settle(MAX_POLLS)
                .map_err(|_| TaskError::Busy { t_ns })?,
        );
        match self.g.busy_queue() {
            Some(queue) => Err(TaskError::Stuck { t_ns, queue }),
            None => Ok(()),
        }
    }

    /// Moves the clock to `t_ns`, stopping at every timer due before.
    fn run_to(&mut self, t_ns: u64) -> Result<(), TaskError> {
        while let Some(due) = self.g.clock.next_timer().filter(|&d| d < t_ns) {
            self.g.clock.advance(due);
            self.settle()?;
        }
        self.g.clock.advance(t_ns);
        self.settle()
    }

    /// Hands `it` to its task, as the DMA interrupt does.
    fn deliver(&mut self, it: &Timed) -> Result<(), TaskError> {
        let (queue, name) = if it.buffers.is_status() {
            (&self.g.raw_status, "RAW_STATUS")
        } else {
            (&self.g.raw_input, "RAW_INPUT")
        };
        queue.try_send(it.clone()).map_err(|_| TaskError::Stuck {
            t_ns: self.g.clock.now(),
            queue: name,
        })?;
        self.settle()
    }
}

/// Runs `items` (time-ordered; see [`super::stimulus`]) through the task graph
/// for `config`, then the clocks up to `end_ns`.
pub fn run(
    config: &Config,
    options: Options,
    items: &[Timed],
    end_ns: u64,
) -> Result<TaskRun, TaskError> {
    let input = Box::new(Input::new(config, &options)?);
    let status = Box::new(HeadStatusIn::new(config, &options)?);
    let g = Rc::new(Graph {
        clock: SimClock::default(),
        core: RefCell::new(Core::new(config, &options)?),
        raw_input: Channel::new(),
        raw_status: Channel::new(),
        events: Channel::new(),
        head_status: Channel::new(),
        error: RefCell::new(None),
        stalls: Cell::new(0),
        checks: Cell::new(0),
        stop: Cell::new(false),
        on_stop: Wakers::default(),
    });

    let exec = SimExecutor::new();
    let spawned = [
        exec.spawn({
            let g = Rc::clone(&g);
            async move { g.until_stopped(line_in(&g, input)).await }
        }),
        exec.spawn({
            let g = Rc::clone(&g);
            async move { g.until_stopped(status_in(&g, status)).await }
        }),
        exec.spawn({
            let g = Rc::clone(&g);
            async move { g.until_stopped(bridge(&g)).await }
        }),
        exec.spawn({
            let g = Rc::clone(&g);
            async move { g.until_stopped(supervisor(&g)).await }
        }),
    ];
    spawned
        .into_iter()
        .collect::<Result<(), _>>()
        .map_err(TaskError::Spawn)?;

    let mut bench = Bench {
        g: &g,
        exec,
        polls: 0,
    };
    bench.settle()?;
    for it in items {
        bench.run_to(it.t_ns)?;
        bench.deliver(it)?;
    }
    bench.run_to(end_ns)?;
    g.stop.set(true);
    g.on_stop.wake_all();
    bench.settle()?;
    let polls = bench.polls;

    let g = Rc::try_unwrap(g).map_err(|g| TaskError::NotStopped {
        tasks: Rc::strong_count(&g) - 1,
    })?;
    if let Some(e) = g.error.into_inner() {
        return Err(e.into());
    }
    Ok(TaskRun {
        core: g.core.into_inner(),
        stalls: g.stalls.get(),
        checks: g.checks.get(),
        polls,
    })
}
