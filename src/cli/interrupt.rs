//! Removes the temporary files of the outputs being written when the run
//! is interrupted (SIGINT, SIGTERM, SIGHUP), so that an interrupted run
//! leaves no partial file behind either: an output is written to a hidden
//! temporary file beside it and renamed into place at the end
//! ([`super::output::Staged`]); a failure removes the file as the run
//! unwinds, a signal would end the process before that.
//!
//! The paths of the files being written sit in a fixed table of atomic
//! pointers; the signal handler takes each one out, unlinks it (both are
//! async-signal-safe), restores the default action and raises the signal
//! again, so the process ends as it would have without the handler.

use std::path::Path;

/// A registered temporary file: taken out of the table when dropped (once
/// the file is renamed into place or removed).
pub(super) struct Guard(#[allow(dead_code)] Option<usize>);

#[cfg(unix)]
mod imp {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStrExt;
    use std::path::Path;
    use std::sync::Once;
    use std::sync::atomic::{AtomicPtr, Ordering};

    use super::Guard;

    /// Temporary files written at once (a run writes one or two per
    /// program, a batch one or two per worker thread); beyond them a file
    /// goes unregistered.
    const SLOTS: usize = 256;

    static PATHS: [AtomicPtr<libc::c_char>; SLOTS] =
        [const { AtomicPtr::new(std::ptr::null_mut()) }; SLOTS];

    static INSTALL: Once = Once::new();

    extern "C" fn on_signal(sig: libc::c_int) {
        for slot in &PATHS {
            let p = slot.swap(std::ptr::null_mut(), Ordering::SeqCst);
            if !p.is_null() {
                // SAFETY: `p` came from `CString::into_raw` and was taken
                // out of the table by this swap alone; it is not freed
                // here (the process ends).
                unsafe {
                    libc::unlink(p);
                }
            }
        }
        // SAFETY: restoring the default action and raising the signal
        // again are async-signal-safe.
        unsafe {
            libc::signal(sig, libc::SIG_DFL);
            libc::raise(sig);
        }
    }

    fn install() {
        INSTALL.call_once(|| {
            for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
                let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
                // SAFETY: the handler only touches atomics and calls
                // async-signal-safe functions.
                unsafe {
                    libc::signal(sig, handler);
                }
            }
        });
    }

    pub(super) fn register(path: &Path) -> Guard {
        install();
        let Ok(c) = CString::new(path.as_os_str().as_bytes()) else {
            return Guard(None);
        };
        let p = c.into_raw();
        for (i, slot) in PATHS.iter().enumerate() {
            if slot
                .compare_exchange(std::ptr::null_mut(), p, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
            {
                return Guard(Some(i));
            }
        }
        // SAFETY: `p` came from `into_raw` just above and was never shared.
        drop(unsafe { CString::from_raw(p) });
        Guard(None)
    }

    impl Drop for Guard {
        fn drop(&mut self) {
            let Some(i) = self.0 else { return };
            let Some(slot) = PATHS.get(i) else { return };
            let p = slot.swap(std::ptr::null_mut(), Ordering::SeqCst);
            if !p.is_null() {
                // SAFETY: the swap took `p` out of the table, so no signal
                // handler holds it; it came from `into_raw`.
                drop(unsafe { CString::from_raw(p) });
            }
        }
    }
}

/// Registers the temporary file `path` for removal on an interrupt, for as
/// long as the guard lives.
pub(super) fn register(path: &Path) -> Guard {
    #[cfg(unix)]
    {
        imp::register(path)
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        Guard(None)
    }
}
