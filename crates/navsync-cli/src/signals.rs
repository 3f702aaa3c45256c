//! SIGINT and SIGTERM: a clean stop. A thread waits for the signal
//! (signal-hook's iterator, so that no work is done in the handler
//! itself), removes every partial file of the run
//! (`navsync::io::output::abandon_temporaries`, which also blocks every
//! later rename onto a final name), says so and exits 128 + the signal
//! (130, 143; the shell's convention). Locks go with the process.
//! `navsync live` replaces the SIGINT handler with its own (a flag that
//! ends the run and writes its files).

/// Installs the handler thread (Unix; elsewhere the default action).
pub fn install() {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) else {
            eprintln!("navsync: note: cannot install the SIGINT/SIGTERM handler");
            return;
        };
        let spawned = std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || {
                if let Some(sig) = signals.forever().next() {
                    let n = navsync::io::output::abandon_temporaries();
                    let name = if sig == SIGINT { "SIGINT" } else { "SIGTERM" };
                    eprintln!(
                        "\nnavsync: interrupted ({name}): removed {n} partial file(s); nothing under a final name is partial"
                    );
                    std::process::exit(128 + sig);
                }
            });
        if spawned.is_err() {
            eprintln!("navsync: note: cannot start the signal thread");
        }
    }
}
