//! Pipelined or inline I/O stages.
//!
//! File readers and writers of a run (`sync`'s rig-log reader and file
//! writer, `fuse`'s IMU reader and navigation writer) are stages that pass
//! batches to and from the computing thread. On a free machine each stage
//! runs on its own thread, so parsing and formatting overlap the filter: a
//! drive then takes about 1.3 cores. A scheduler that pins one core per
//! task (Ray's `num_cpus=1`, a one-core container) wants the stages inline
//! on the caller's thread instead: one task, one core (`navsync batch
//! --single-core`, the Python fleet's `single_core=True`). The same kind
//! of switch exists for numerical libraries (`OMP_NUM_THREADS=1`). Measured
//! on 2 cores with 2 drives at a time, the threads still gain about 5 %
//! (reading and writing fill the other drive's waits), so they stay the
//! default.
//!
//! The choice is process-wide: [`set_io_threads`], or the environment
//! variable `NAVSYNC_IO_THREADS=0` read at the first use. Results are the
//! same either way; only the wall time and the cores used differ.
#![warn(missing_docs)]

use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;

use crate::error::Error;

/// 0: not decided yet (read the environment), 1: threads, 2: inline.
static IO_THREADS: AtomicU8 = AtomicU8::new(0);

/// Runs the I/O stages of later runs in this process on their own threads
/// (`true`, the default) or inline on the caller's thread (`false`).
pub fn set_io_threads(enabled: bool) {
    IO_THREADS.store(if enabled { 1 } else { 2 }, Ordering::Relaxed);
}

/// Whether I/O stages get their own threads: [`set_io_threads`]'s choice,
/// else `NAVSYNC_IO_THREADS` (`0`, `false`, `no`, `off` mean inline), else
/// yes.
pub fn io_threads() -> bool {
    match IO_THREADS.load(Ordering::Relaxed) {
        1 => true,
        2 => false,
        _ => {
            let on = std::env::var("NAVSYNC_IO_THREADS").map_or(true, |v| {
                !matches!(
                    v.trim().to_ascii_lowercase().as_str(),
                    "0" | "false" | "no" | "off"
                )
            });
            set_io_threads(on);
            on
        }
    }
}

/// A source of batches (a file reader).
pub(crate) trait Producer: Send + 'static {
    type Item: Send + 'static;
    /// What the reader reports when it is done (counts, notes).
    type Output: Send + 'static;
    /// The next batch; `None` at the end.
    fn next_batch(&mut self) -> Result<Option<Vec<Self::Item>>, Error>;
    fn finish(self) -> Result<Self::Output, Error>;
}

/// A sink of batches (a file writer).
pub(crate) trait Consumer: Send + 'static {
    type Item: Send + 'static;
    type Output: Send + 'static;
    fn consume(&mut self, batch: Vec<Self::Item>) -> Result<(), Error>;
    fn finish(self) -> Result<Self::Output, Error>;
}

/// Up to `cap` items from `next` (a reader's next record); `None` when the
/// reader had nothing left: the `next_batch` of a file reader.
pub(crate) fn fill_batch<T>(
    cap: usize,
    mut next: impl FnMut() -> Result<Option<T>, Error>,
) -> Result<Option<Vec<T>>, Error> {
    let mut batch = Vec::with_capacity(cap);
    while batch.len() < cap {
        match next()? {
            Some(x) => batch.push(x),
            None => break,
        }
    }
    Ok((!batch.is_empty()).then_some(batch))
}

fn failed(name: &str) -> Error {
    Error::Invalid(format!("the {name} thread panicked"))
}

/// Batches channelled between a stage thread and the caller.
const DEPTH: usize = 8;

/// A producer, on its own thread or inline.
pub(crate) enum Source<P: Producer> {
    Threaded {
        rx: mpsc::Receiver<Vec<P::Item>>,
        handle: JoinHandle<Result<P::Output, Error>>,
        name: &'static str,
    },
    Inline(P),
}

impl<P: Producer> Source<P> {
    /// Starts `producer` as [`io_threads`] says.
    pub(crate) fn start(producer: P, name: &'static str) -> Result<Self, Error> {
        Self::new(producer, name, io_threads())
    }

    /// Starts `producer` on its own thread (`threaded`) or inline.
    pub(crate) fn new(mut producer: P, name: &'static str, threaded: bool) -> Result<Self, Error> {
        if !threaded {
            return Ok(Source::Inline(producer));
        }
        let (tx, rx) = mpsc::sync_channel::<Vec<P::Item>>(DEPTH);
        let handle = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                while let Some(batch) = producer.next_batch()? {
                    if tx.send(batch).is_err() {
                        break;
                    }
                }
                producer.finish()
            })
            .map_err(|e| Error::Invalid(format!("cannot start the {name} thread: {e}")))?;
        Ok(Source::Threaded { rx, handle, name })
    }

    /// The next batch. A threaded producer's error comes from
    /// [`Source::finish`] (the batch stream just ends).
    pub(crate) fn next_batch(&mut self) -> Result<Option<Vec<P::Item>>, Error> {
        match self {
            Source::Threaded { rx, .. } => Ok(rx.recv().ok()),
            Source::Inline(p) => p.next_batch(),
        }
    }

    /// Stops reading (whatever is left is not read) and returns the
    /// producer's output or its error.
    pub(crate) fn finish(self) -> Result<P::Output, Error> {
        match self {
            Source::Threaded { rx, handle, name } => {
                drop(rx);
                handle.join().map_err(|_| failed(name))?
            }
            Source::Inline(p) => p.finish(),
        }
    }
}

/// A consumer, on its own thread or inline. Dropped without
/// [`Drain::finish`] (the run failed), its consumer is dropped unfinished
/// in both modes: a writer's file is then never committed under its final
/// name. (The threaded stage used to finish on its own when the channel
/// closed, so a run stopped by a diverged solution left a `navresult.nav`
/// holding the diverged states.)
pub(crate) enum Drain<C: Consumer> {
    Threaded {
        tx: Option<mpsc::SyncSender<Vec<C::Item>>>,
        /// `None` once a failed send has collected the thread's error.
        handle: Option<JoinHandle<Result<C::Output, Error>>>,
        name: &'static str,
        /// Set before the channel closes when the drain is dropped
        /// unfinished: the thread then drops its consumer unfinished.
        abandoned: Arc<AtomicBool>,
    },
    /// `None` once finished.
    Inline(Option<C>),
}

impl<C: Consumer> Drop for Drain<C> {
    fn drop(&mut self) {
        if let Drain::Threaded {
            tx,
            handle,
            abandoned,
            ..
        } = self
            && tx.is_some()
        {
            abandoned.store(true, Ordering::SeqCst);
            tx.take();
            // Waits for the consumer to be dropped (its temporaries
            // removed) before the caller goes on to report the error.
            if let Some(h) = handle.take() {
                let _ = h.join();
            }
        }
    }
}

impl<C: Consumer> Drain<C> {
    /// Starts `consumer` as [`io_threads`] says.
    pub(crate) fn start(consumer: C, name: &'static str) -> Result<Self, Error> {
        Self::new(consumer, name, io_threads())
    }

    /// Starts `consumer` on its own thread (`threaded`) or inline.
    pub(crate) fn new(mut consumer: C, name: &'static str, threaded: bool) -> Result<Self, Error> {
        if !threaded {
            return Ok(Drain::Inline(Some(consumer)));
        }
        let (tx, rx) = mpsc::sync_channel::<Vec<C::Item>>(DEPTH);
        let abandoned = Arc::new(AtomicBool::new(false));
        let abandoned_in_thread = Arc::clone(&abandoned);
        let handle = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                for batch in rx {
                    consumer.consume(batch)?;
                }
                if abandoned_in_thread.load(Ordering::SeqCst) {
                    drop(consumer);
                    return Err(Error::Invalid(format!("the {name} stage was abandoned")));
                }
                consumer.finish()
            })
            .map_err(|e| Error::Invalid(format!("cannot start the {name} thread: {e}")))?;
        Ok(Drain::Threaded {
            tx: Some(tx),
            handle: Some(handle),
            name,
            abandoned,
        })
    }

    /// Hands over a batch. A consumer that failed returns its error here
    /// (a threaded one: at the first send after it stopped).
    pub(crate) fn send(&mut self, batch: Vec<C::Item>) -> Result<(), Error> {
        match self {
            Drain::Threaded {
                tx, handle, name, ..
            } => {
                if tx.as_ref().is_some_and(|t| t.send(batch).is_ok()) {
                    return Ok(());
                }
                tx.take();
                match handle.take().map(|h| h.join()) {
                    Some(Ok(Err(e))) => Err(e),
                    Some(Err(_)) => Err(failed(name)),
                    _ => Err(Error::Invalid(format!("the {name} thread has stopped"))),
                }
            }
            Drain::Inline(c) => match c.as_mut() {
                Some(c) => c.consume(batch),
                None => Err(Error::Invalid("the writer has stopped".into())),
            },
        }
    }

    /// Waits for everything sent to be consumed; the consumer's output.
    pub(crate) fn finish(mut self) -> Result<C::Output, Error> {
        match &mut self {
            Drain::Threaded {
                tx, handle, name, ..
            } => {
                // The channel closes without `abandoned`: the thread
                // finishes its consumer.
                tx.take();
                let name = *name;
                match handle.take() {
                    Some(h) => h.join().map_err(|_| failed(name))?,
                    None => Err(Error::Invalid(format!("the {name} thread has stopped"))),
                }
            }
            Drain::Inline(c) => match c.take() {
                Some(c) => c.finish(),
                None => Err(Error::Invalid("the writer has stopped".into())),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Count {
        next: u32,
        end: u32,
        fail_at: Option<u32>,
    }
    impl Producer for Count {
        type Item = u32;
        type Output = u32;
        fn next_batch(&mut self) -> Result<Option<Vec<u32>>, Error> {
            if self.fail_at == Some(self.next) {
                return Err(Error::Invalid("bad record".into()));
            }
            if self.next >= self.end {
                return Ok(None);
            }
            let b: Vec<u32> = (self.next..(self.next + 3).min(self.end)).collect();
            self.next += b.len() as u32;
            Ok(Some(b))
        }
        fn finish(self) -> Result<u32, Error> {
            Ok(self.next)
        }
    }
    struct Sum(u64);
    impl Consumer for Sum {
        type Item = u32;
        type Output = u64;
        fn consume(&mut self, batch: Vec<u32>) -> Result<(), Error> {
            self.0 += batch.iter().map(|&v| v as u64).sum::<u64>();
            Ok(())
        }
        fn finish(self) -> Result<u64, Error> {
            Ok(self.0)
        }
    }

    fn run(threads: bool, fail_at: Option<u32>) -> Result<(u32, u64), Error> {
        // Both modes chosen directly: the process-wide switch is left alone
        // (tests run in parallel).
        let p = Count {
            next: 0,
            end: 100,
            fail_at,
        };
        let mut src = Source::new(p, "test reader", threads)?;
        let mut drain = Drain::new(Sum(0), "test writer", threads)?;
        let mut read_err = None;
        loop {
            match src.next_batch() {
                Ok(Some(b)) => drain.send(b)?,
                Ok(None) => break,
                Err(e) => {
                    read_err = Some(e);
                    break;
                }
            }
        }
        let n = src.finish();
        if let Some(e) = read_err {
            return Err(e);
        }
        Ok((n?, drain.finish()?))
    }

    #[test]
    fn threaded_and_inline_stages_deliver_the_same_batches() {
        assert_eq!(run(true, None).unwrap(), (100, 4950));
        assert_eq!(run(false, None).unwrap(), (100, 4950));
    }

    #[test]
    fn a_producer_error_reaches_the_caller_in_both_modes() {
        assert!(run(true, Some(30)).is_err());
        assert!(run(false, Some(30)).is_err());
    }

    struct FailsAtSecond(usize);
    impl Consumer for FailsAtSecond {
        type Item = u32;
        type Output = ();
        fn consume(&mut self, _: Vec<u32>) -> Result<(), Error> {
            self.0 += 1;
            if self.0 == 2 {
                return Err(Error::Invalid("disk full".into()));
            }
            Ok(())
        }
        fn finish(self) -> Result<(), Error> {
            Ok(())
        }
    }

    /// Records whether it was finished.
    struct Finishes(Arc<AtomicBool>);
    impl Consumer for Finishes {
        type Item = u32;
        type Output = ();
        fn consume(&mut self, _: Vec<u32>) -> Result<(), Error> {
            Ok(())
        }
        fn finish(self) -> Result<(), Error> {
            self.0.store(true, Ordering::SeqCst);
            Ok(())
        }
    }

    /// A run that fails drops its writer unfinished: the consumer is not
    /// finished (a file writer's temporary is not committed) in either
    /// mode, and is finished when the drain is.
    #[test]
    fn a_drain_dropped_unfinished_does_not_finish_its_consumer() {
        for threads in [true, false] {
            let finished = Arc::new(AtomicBool::new(false));
            let mut drain =
                Drain::new(Finishes(Arc::clone(&finished)), "test writer", threads).unwrap();
            drain.send(vec![1, 2, 3]).unwrap();
            drop(drain);
            assert!(!finished.load(Ordering::SeqCst), "threads {threads}");
            let finished = Arc::new(AtomicBool::new(false));
            let mut drain =
                Drain::new(Finishes(Arc::clone(&finished)), "test writer", threads).unwrap();
            drain.send(vec![1, 2, 3]).unwrap();
            drain.finish().unwrap();
            assert!(finished.load(Ordering::SeqCst), "threads {threads}");
        }
    }

    #[test]
    fn a_consumer_error_reaches_the_caller_in_both_modes() {
        for threads in [true, false] {
            let mut drain = Drain::new(FailsAtSecond(0), "test writer", threads).unwrap();
            let mut first_err = None;
            for k in 0..50u32 {
                if let Err(e) = drain.send(vec![k]) {
                    first_err = Some(e);
                    break;
                }
            }
            let err = match first_err {
                Some(e) => e,
                None => drain.finish().unwrap_err(),
            };
            assert!(err.to_string().contains("disk full"), "{threads}: {err}");
        }
    }
}
