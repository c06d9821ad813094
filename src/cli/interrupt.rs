//! Removes the temporary files of the outputs being written when a signal
//! ends the run, so that a run ended from outside leaves no partial file
//! behind: an output is written to a hidden temporary file beside it
//! (`.postproc-PID-N-XXXXXXXX`, [`create_temp`]) and renamed into place at
//! the end ([`super::output::Staged`]); a failure removes the file as the
//! run unwinds, a signal would end the process before that.
//!
//! Every signal whose default action ends the process and that can be
//! caught is handled ([`TERMINATING`]: INT, TERM, HUP, QUIT, USR1, USR2,
//! ALRM, XFSZ, XCPU, VTALRM, PROF, PIPE, ABRT and the platform's others),
//! unless the process was started with it ignored (`nohup`, a shell's
//! `trap '' HUP`; Rust ignores PIPE itself, so a closed pipe is a write
//! error and the run unwinds). SIGKILL cannot be caught: the next run that
//! writes into the same folder removes the temporary files of processes
//! that no longer exist ([`remove_stale`]).
//!
//! The paths of the files being written sit in a fixed table of atomic
//! pointers; the signal handler takes each one out, unlinks it (both are
//! async-signal-safe), restores the default action and raises the signal
//! again, so the process ends as it would have without the handler. A
//! path is registered before its file is created, so no signal can fall
//! between the two.

use std::fs::File;
use std::path::{Path, PathBuf};

/// A registered temporary file: taken out of the table when dropped (once
/// the file is renamed into place or removed).
pub(super) struct Guard(#[allow(dead_code)] Option<usize>);

/// Prefix of every temporary output file.
const PREFIX: &str = ".postproc-";

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

    /// The signals whose default action ends the process and that a
    /// handler can catch (SIGKILL and SIGSTOP cannot be; SIGSEGV, SIGBUS,
    /// SIGILL, SIGFPE and SIGTRAP are faults of the process itself, and
    /// SIGSEGV and SIGBUS carry Rust's stack-overflow report).
    const TERMINATING: &[libc::c_int] = &[
        libc::SIGINT,
        libc::SIGTERM,
        libc::SIGHUP,
        libc::SIGQUIT,
        libc::SIGUSR1,
        libc::SIGUSR2,
        libc::SIGALRM,
        libc::SIGXFSZ,
        libc::SIGXCPU,
        libc::SIGVTALRM,
        libc::SIGPROF,
        libc::SIGPIPE,
        libc::SIGABRT,
        libc::SIGSYS,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        libc::SIGPOLL,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        libc::SIGPWR,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        libc::SIGSTKFLT,
    ];

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
            for &sig in TERMINATING {
                // SAFETY: a zeroed sigaction is a valid "query" argument;
                // the handler only touches atomics and calls
                // async-signal-safe functions.
                unsafe {
                    let mut old: libc::sigaction = std::mem::zeroed();
                    if libc::sigaction(sig, std::ptr::null(), &mut old) != 0
                        || old.sa_sigaction == libc::SIG_IGN
                    {
                        // Ignored by whoever started the run: it does not
                        // end the process, so it stays ignored.
                        continue;
                    }
                    let mut new: libc::sigaction = std::mem::zeroed();
                    new.sa_sigaction =
                        on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
                    libc::sigemptyset(&mut new.sa_mask);
                    new.sa_flags = libc::SA_RESTART;
                    libc::sigaction(sig, &new, std::ptr::null_mut());
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

    /// Whether process `pid` is gone (no such process).
    pub(super) fn gone(pid: u32) -> bool {
        let Ok(pid) = libc::pid_t::try_from(pid) else {
            return false;
        };
        if pid <= 0 {
            return false;
        }
        // SAFETY: signal 0 only checks that the process exists.
        let r = unsafe { libc::kill(pid, 0) };
        r != 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH)
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

/// Registers the temporary file `path` for removal on a terminating
/// signal, for as long as the guard lives.
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

/// Creates a new private temporary file in `dir`, registered for removal
/// on a terminating signal before it exists: its path (deleted when the
/// [`tempfile::TempPath`] is dropped), the open file and the guard. The
/// name holds the process id, so that [`remove_stale`] can tell the files
/// of a process that was killed.
pub(super) fn create_temp(dir: &Path) -> std::io::Result<(tempfile::TempPath, File, Guard)> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    remove_stale(dir);
    let pid = std::process::id();
    for _ in 0..100 {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let path = dir.join(format!("{PREFIX}{pid}-{n}-{nanos:08x}"));
        let guard = register(&path);
        let mut options = std::fs::OpenOptions::new();
        options.write(true).create_new(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::OpenOptionsExt;
            options.mode(0o600);
        }
        match options.open(&path) {
            Ok(file) => {
                return match tempfile::TempPath::try_from_path(&path) {
                    Ok(tmp) => Ok((tmp, file, guard)),
                    Err(e) => {
                        let _ = std::fs::remove_file(&path);
                        Err(e)
                    }
                };
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                // Not ours: the guard must not remove it.
                drop(guard);
            }
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        "no free temporary file name",
    ))
}

/// The process id in a temporary file's name, `.postproc-PID-…`.
fn owner_pid(name: &str) -> Option<u32> {
    let rest = name.strip_prefix(PREFIX)?;
    let (pid, tail) = rest.split_once('-')?;
    if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) || tail.is_empty() {
        return None;
    }
    pid.parse().ok()
}

/// Removes the temporary files of `dir` left by processes that are gone
/// (killed with SIGKILL, or the machine lost power), checked once per
/// folder and run. (A run of another machine writing into a shared folder
/// has a process id that means nothing here: at worst its file is removed
/// and its rename fails with an error, nothing wrong is left in place.)
fn remove_stale(dir: &Path) {
    use std::collections::BTreeSet;
    use std::sync::Mutex;
    static DONE: Mutex<BTreeSet<PathBuf>> = Mutex::new(BTreeSet::new());
    let key = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
    let first = DONE.lock().is_ok_and(|mut done| done.insert(key));
    if !first {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = owner_pid(&name.to_string_lossy()) else {
            continue;
        };
        let file = entry.file_type().is_ok_and(|t| t.is_file());
        if file && pid != std::process::id() && gone(pid) {
            tracing::debug!(
                "removing {} left by a process that ended",
                name.to_string_lossy()
            );
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

fn gone(pid: u32) -> bool {
    #[cfg(unix)]
    {
        imp::gone(pid)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_owner_of_a_temporary_file_is_read_from_its_name() {
        assert_eq!(owner_pid(".postproc-1234-0-0badf00d"), Some(1234));
        assert_eq!(owner_pid(".postproc-abc123"), None);
        assert_eq!(owner_pid(".postproc-1234"), None);
        assert_eq!(owner_pid("postproc-1234-0-1"), None);
    }

    #[test]
    fn a_temporary_file_is_private_and_removed_with_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let (path, file, guard) = create_temp(dir.path()).unwrap();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(owner_pid(&name), Some(std::process::id()));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = file.metadata().unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let kept = path.to_path_buf();
        drop((path, file, guard));
        assert!(!kept.exists());
    }
}
