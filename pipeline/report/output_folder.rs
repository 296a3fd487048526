//! An output folder replaced as a whole: a reader sees the previous set of
//! outputs or the new one, never a mix. A job writes into a work folder
//! beside its target (`.<name>.servoid-<pid>`), started as hard links of
//! the previous set (the cache, the history and the lab's own files carried
//! without copying; every writer replaces by rename, so they are never
//! touched through the links), and the two are exchanged in one step
//! (renameat2 with RENAME_EXCHANGE on Linux). The job holds a flock on
//! `.<name>.servoid-lock` beside the folder, released by the kernel when it
//! ends or dies; a second job waits for it up to `--wait` ([`DEFAULT_WAIT`])
//! and names it, then starts from the set it left. A work folder left by a
//! killed job is unlocked, and the next job removes it.
//!
//! Fault injection: `SERVOID_KILL_AT=<point>` (`locked`, `carried`,
//! `results`, `exchange`, `exchanged`) makes the process SIGKILL itself
//! there; tests/output_set.rs kills reruns where a mix would be likeliest.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::{WriteError, settle};

/// How long a job waits for another holding its output folder, unless
/// `--wait` says: half an hour, longer than a night of hundreds of logs
/// takes on two cores, and short enough that a stopped or hung holder is
/// reported the same night.
pub const DEFAULT_WAIT: Duration = Duration::from_secs(1800);

/// The infix of work folders beside a target, `.<name>.servoid-<pid>`.
const WORK: &str = ".servoid-";

/// A set of outputs being written; [`OutputFolder::commit`] puts it in place of
/// the target. Dropped without a commit (an error), it is removed and the
/// target is left as it was.
#[derive(Debug)]
pub struct OutputFolder {
    /// The output folder, absolute, symbolic links resolved: what is
    /// replaced.
    resolved: PathBuf,
    /// The output folder as given, for what is shown (messages, outcome
    /// paths).
    target: PathBuf,
    work: PathBuf,
    /// Held for the job's life: an unlocked work folder is a dead job's.
    _lock: File,
    /// The output folder's lock, held from before the previous set is
    /// carried until the new one is in place (or the job ends).
    _target_lock: File,
    committed: bool,
}

impl OutputFolder {
    /// Check that `target` can take the outputs (it is not a file, its
    /// folder can be made and written), remove dead jobs' work folders
    /// beside it and start a work folder holding the previous set.
    pub fn begin(target: &Path, wait: Duration) -> Result<Self, WriteError> {
        let bad = |why: String| WriteError::OutFolder {
            path: target.to_path_buf(),
            why,
        };
        let existing = std::fs::metadata(target).ok();
        let resolved = resolve_target(target, existing.as_ref()).map_err(bad)?;
        let (Some(parent), Some(name)) = (resolved.parent(), resolved.file_name()) else {
            return Err(bad(
                "the output folder (--out) cannot be a file system's root; give a folder of its own"
                    .into(),
            ));
        };
        check_room(target, &resolved, existing.is_some()).map_err(bad)?;
        std::fs::create_dir_all(parent)
            .map_err(|e| bad(format!("cannot create the output folder (--out): {e}")))?;
        if existing.is_some() {
            probe(&resolved)
                .map_err(|e| bad(format!("cannot write in the output folder (--out): {e}")))?;
        }
        let name = name.to_string_lossy().into_owned();
        let target_lock = lock_target(parent, &name, target, wait).map_err(|e| {
            bad(format!(
                "cannot lock the output folder (--out) for this job: {e}"
            ))
        })?;
        sweep(parent, &name);
        if existing.is_none() && std::fs::symlink_metadata(&resolved).is_ok() {
            // The sweep put a previous set back (or a job this one waited
            // for put its set in): start again from it.
            drop(target_lock);
            return Self::begin(target, wait);
        }
        let (work, lock) = start_work(parent, &name).map_err(bad)?;
        let set = Self {
            resolved,
            target: target.to_path_buf(),
            work,
            _lock: lock,
            _target_lock: target_lock,
            committed: false,
        };
        if existing.is_some() {
            if let Ok(m) = std::fs::metadata(&set.resolved) {
                let _ = std::fs::set_permissions(&set.work, m.permissions());
            }
            carry(&set.resolved, &set.work).map_err(|e| set.relocate(e))?;
        }
        fault("carried");
        Ok(set)
    }

    /// The folder the job writes into.
    pub fn dir(&self) -> &Path {
        &self.work
    }

    /// The output folder as it was given.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// The output folder, absolute, symbolic links resolved.
    pub fn resolved(&self) -> &Path {
        &self.resolved
    }

    /// `path` as it will be once the set is in place: a path under the
    /// work folder is moved under the target (as given); others are kept.
    pub fn final_path(&self, path: &Path) -> PathBuf {
        match path.strip_prefix(&self.work) {
            Ok(rest) if rest.as_os_str().is_empty() => self.target.clone(),
            Ok(rest) => self.target.join(rest),
            Err(_) => path.to_path_buf(),
        }
    }

    /// A write error as the user should read it: paths under the target,
    /// not under the work folder.
    pub fn relocate(&self, e: WriteError) -> WriteError {
        e.map_paths(&|p| self.final_path(p))
    }

    /// Make the set durable and put it in place of the target in one step;
    /// the previous set is removed. Returns the target as given.
    pub fn commit(mut self) -> Result<PathBuf, WriteError> {
        let io = |path: &Path, source| WriteError::Io {
            path: path.to_path_buf(),
            source,
        };
        settle(&self.work).map_err(|e| self.relocate(e))?;
        fault("exchange");
        let old = exchange(&self.work, &self.resolved).map_err(|e| io(&self.target, e))?;
        self.committed = true;
        fault("exchanged");
        if let Some(parent) = self.resolved.parent()
            && let Ok(d) = File::open(parent)
        {
            // The exchange itself is durable once the folder holding both
            // names is.
            d.sync_all().map_err(|e| io(parent, e))?;
        }
        if let Some(old) = old {
            let _ = std::fs::remove_dir_all(old);
        }
        Ok(self.target.clone())
    }
}

impl Drop for OutputFolder {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.work);
        }
    }
}

/// With `SERVOID_KILL_AT=point` in the environment, kill this process (as
/// the kernel's OOM killer or an operator's kill -9 would) at `point`.
pub fn fault(point: &str) {
    // SERVOID_PAUSE_AT=<point> holds the job there for SERVOID_PAUSE_MS
    // (tests/output_set.rs starts a second job into a locked folder).
    if std::env::var_os("SERVOID_PAUSE_AT").is_some_and(|p| p == point) {
        let ms = std::env::var("SERVOID_PAUSE_MS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1000);
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
    if std::env::var_os("SERVOID_KILL_AT").is_some_and(|p| p == point) {
        #[cfg(unix)]
        // SAFETY: raise only sends a signal to this process.
        unsafe {
            libc::raise(libc::SIGKILL);
        }
        #[cfg(not(unix))]
        std::process::abort();
    }
}

/// The output folder to replace: `target` absolute, and, when it exists
/// (`existing`), its symbolic links resolved; refused when it is a file.
/// The error is why, for [`WriteError::OutFolder`].
fn resolve_target(target: &Path, existing: Option<&std::fs::Metadata>) -> Result<PathBuf, String> {
    if existing.is_some_and(|m| !m.is_dir()) {
        return Err(
            "the output folder (--out) is a file; give a folder, or remove the file".into(),
        );
    }
    let abs = std::path::absolute(target)
        .map_err(|e| format!("cannot resolve the output folder (--out): {e}"))?;
    // A symbolic link (reports/latest -> reports/2026-11-23) keeps
    // pointing where it did: the folder it names is what is replaced.
    match existing {
        Some(_) => std::fs::canonicalize(&abs)
            .map_err(|e| format!("cannot resolve the output folder (--out): {e}")),
        None => Ok(abs),
    }
}

/// Whether the output folder has room of its own: it does not hold the
/// current folder (which replacing it would pull away), and no file stands
/// where a folder above it must be. The error is why, for
/// [`WriteError::OutFolder`].
fn check_room(target: &Path, resolved: &Path, exists: bool) -> Result<(), String> {
    if let Ok(cwd) = std::env::current_dir().and_then(std::fs::canonicalize)
        && exists
        && cwd.starts_with(resolved)
    {
        return Err(
            "the output folder (--out) holds the current folder, and servoid replaces its output folder as a whole; give a folder of its own, such as reports/<name>"
                .into(),
        );
    }
    // Named as given: the user wrote `f/out`, not its absolute path.
    if let Some(file) = target
        .ancestors()
        .skip(1)
        .filter(|a| !a.as_os_str().is_empty())
        .find(|a| std::fs::symlink_metadata(a).is_ok())
        .filter(|a| !a.is_dir())
    {
        return Err(format!(
            "{} is a file, so the output folder (--out) cannot be made under it; give a folder elsewhere, or remove the file",
            file.display()
        ));
    }
    Ok(())
}

/// This job's work folder beside the output folder `name` in `parent`,
/// made and locked. The error is why, for [`WriteError::OutFolder`].
fn start_work(parent: &Path, name: &str) -> Result<(PathBuf, File), String> {
    let work = parent.join(format!(".{name}{WORK}{}", std::process::id()));
    // A folder of this name is a dead job's whose pid came round again
    // (sweep found it unlocked), or a live one in this process.
    if work.exists() {
        return Err(format!(
            "{} is in use by another job of this process",
            work.display()
        ));
    }
    std::fs::create_dir(&work)
        .map_err(|e| format!("cannot write beside the output folder (--out): {e}"))?;
    let lock = File::open(&work).and_then(|f| f.try_lock().map(|()| f).map_err(Into::into));
    match lock {
        Ok(f) => Ok((work, f)),
        Err(e) => {
            let _ = std::fs::remove_dir_all(&work);
            Err(format!("cannot lock the work folder: {e}"))
        }
    }
}

/// The lock of output folder `name` in `parent`, taken: at once, or when
/// the job holding it ends, waiting at most `wait` (with a message naming
/// the holder on stderr). The file stays (a later job reuses it); only the
/// kernel's lock on it matters. It holds the holder's pid and command line,
/// so a job that waits can say who it waits for.
fn lock_target(parent: &Path, name: &str, shown: &Path, wait: Duration) -> std::io::Result<File> {
    use std::io::{Read, Seek, Write};
    let path = parent.join(format!(".{name}{WORK}lock"));
    let mut file = File::options()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(&path)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut text = String::new();
            let _ = file.read_to_string(&mut text);
            let holder = Holder::from_lock(&text);
            eprintln!(
                "servoid: the output folder {} is being written by another job ({holder}); waiting up to {} s for it to finish (--wait)",
                shown.display(),
                wait.as_secs()
            );
            if !wait_for_lock(&file, wait)? {
                return Err(std::io::Error::other(format!(
                    "another job ({holder}) still holds it after {} s (--wait); if that job is stopped or hung, end it, or give a longer --wait",
                    wait.as_secs()
                )));
            }
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(e),
    }
    file.set_len(0)?;
    file.rewind()?;
    let command: Vec<String> = std::env::args().collect();
    write!(file, "{}\n{}", std::process::id(), command.join(" "))?;
    fault("locked");
    Ok(file)
}

/// The lock of the output folder `path` is in, taken (waiting at most
/// `wait`), when it is in one: a folder a job has written, whose lock file
/// lies beside it. None for a file elsewhere.
pub fn lock_if_output(path: &Path, wait: Duration) -> std::io::Result<Option<File>> {
    let Some(folder) = path.parent().filter(|p| !p.as_os_str().is_empty()) else {
        return Ok(None);
    };
    let folder = folder.canonicalize()?;
    let (Some(parent), Some(name)) = (folder.parent(), folder.file_name()) else {
        return Ok(None);
    };
    let name = name.to_string_lossy();
    if !parent.join(format!(".{name}{WORK}lock")).is_file() {
        return Ok(None);
    }
    lock_target(parent, &name, &folder, wait).map(Some)
}

/// Whether `file`'s lock was taken within `wait`: tried every 50 ms, as
/// flock has no timed wait.
fn wait_for_lock(file: &File, wait: Duration) -> std::io::Result<bool> {
    let until = std::time::Instant::now() + wait;
    loop {
        match file.try_lock() {
            Ok(()) => return Ok(true),
            Err(std::fs::TryLockError::WouldBlock) => {}
            Err(std::fs::TryLockError::Error(e)) => return Err(e),
        }
        let now = std::time::Instant::now();
        if now >= until {
            return Ok(false);
        }
        std::thread::sleep(Duration::from_millis(50).min(until - now));
    }
}

/// The job a lock file names: its pid, command line and, where the system
/// says (Linux's /proc), whether it is stopped.
struct Holder {
    pid: Option<u32>,
    command: Option<String>,
}

impl Holder {
    fn from_lock(text: &str) -> Self {
        let mut lines = text.lines();
        Self {
            pid: lines.next().and_then(|l| l.trim().parse().ok()),
            command: lines.next().map(str::to_string).filter(|c| !c.is_empty()),
        }
    }

    /// "T" (stopped) or "t" (traced) in /proc/<pid>/stat's state field.
    fn stopped(&self) -> bool {
        let Some(pid) = self.pid else {
            return false;
        };
        std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
            stat.rsplit_once(')')
                .and_then(|(_, rest)| rest.split_whitespace().next())
                .is_some_and(|state| matches!(state, "T" | "t"))
        })
    }
}

impl std::fmt::Display for Holder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.pid {
            Some(pid) => write!(f, "pid {pid}")?,
            None => write!(f, "pid unknown")?,
        }
        if let Some(c) = &self.command {
            write!(f, ", `{c}`")?;
        }
        if self.stopped() {
            write!(
                f,
                ", stopped (SIGSTOP): it will not finish until it is continued"
            )?;
        }
        Ok(())
    }
}

/// Create and remove a file in `dir`: can this job write there?
fn probe(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(format!(".servoid-probe-{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)
}

/// Remove the work folders dead jobs left beside `name` in `parent`: those
/// nobody holds a lock on. A live job's is locked and kept.
fn sweep(parent: &Path, name: &str) {
    let prefix = format!(".{name}{WORK}");
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for e in entries.flatten() {
        let file_name = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = file_name.strip_prefix(&prefix) else {
            continue;
        };
        let path = e.path();
        // A previous set renamed aside where names cannot be exchanged
        // (see `exchange`): a job killed before its own set went in leaves
        // no output folder, and the previous set is put back.
        if let Some(pid) = pid.strip_suffix("-old")
            && is_pid(pid)
        {
            let target = parent.join(name);
            if std::fs::symlink_metadata(&target).is_err() {
                let _ = std::fs::rename(&path, &target);
            } else {
                let _ = std::fs::remove_dir_all(&path);
            }
            continue;
        }
        if !is_pid(pid) {
            continue;
        }
        let unlocked = File::open(&path).is_ok_and(|f| f.try_lock().is_ok());
        if unlocked {
            let _ = std::fs::remove_dir_all(&path);
        }
    }
}

/// Whether `name` is a temporary that a killed writer left: a per-file
/// temporary (`.<file>.tmp-<pid>`) or a writability probe.
fn stale(name: &str) -> bool {
    let pid_after = |marker: &str| {
        name.starts_with('.') && name.rsplit_once(marker).is_some_and(|(_, pid)| is_pid(pid))
    };
    pid_after(".tmp-") || pid_after(".servoid-probe-")
}

/// Whether `s` is a process id as servoid writes it into a name: decimal
/// digits, at least one.
fn is_pid(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
}

/// Rebuild the tree `from` under `to` with hard links (a copy where the
/// file system has none), leaving out stale temporaries. Symbolic links are
/// recreated as they are; FIFOs, sockets and devices are not carried.
fn carry(from: &Path, to: &Path) -> Result<(), WriteError> {
    let io = |path: &Path, source| WriteError::Io {
        path: path.to_path_buf(),
        source,
    };
    let entries = std::fs::read_dir(from).map_err(|e| io(from, e))?;
    for e in entries {
        let e = e.map_err(|e| io(from, e))?;
        let name = e.file_name();
        if stale(&name.to_string_lossy()) {
            continue;
        }
        let (src, dst) = (e.path(), to.join(&name));
        let kind = e.file_type().map_err(|e| io(&src, e))?;
        if kind.is_dir() {
            std::fs::create_dir(&dst).map_err(|e| io(&dst, e))?;
            if let Ok(m) = std::fs::metadata(&src) {
                let _ = std::fs::set_permissions(&dst, m.permissions());
            }
            carry(&src, &dst)?;
        } else if kind.is_file() {
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst).map_err(|e| io(&dst, e))?;
            }
        } else if kind.is_symlink() {
            #[cfg(unix)]
            {
                let link = std::fs::read_link(&src).map_err(|e| io(&src, e))?;
                std::os::unix::fs::symlink(link, &dst).map_err(|e| io(&dst, e))?;
            }
        }
    }
    Ok(())
}

/// Put `work` in place of `target`. Returns where the previous set now is,
/// to be removed; None when there was none.
///
/// On Linux both names are exchanged in one step. Where the file system
/// cannot (ENOSYS, EINVAL: some network file systems), the target is
/// renamed aside and the work folder renamed in: a reader in between finds
/// no folder, never a mix.
fn exchange(work: &Path, target: &Path) -> std::io::Result<Option<PathBuf>> {
    if std::fs::symlink_metadata(target).is_err() {
        std::fs::rename(work, target)?;
        return Ok(None);
    }
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_bytes());
        let (a, b) = (c(work)?, c(target)?);
        // SAFETY: both are NUL-terminated paths that live across the call.
        let r = unsafe {
            libc::renameat2(
                libc::AT_FDCWD,
                a.as_ptr(),
                libc::AT_FDCWD,
                b.as_ptr(),
                libc::RENAME_EXCHANGE,
            )
        };
        if r == 0 {
            return Ok(Some(work.to_path_buf()));
        }
        let e = std::io::Error::last_os_error();
        if !matches!(e.raw_os_error(), Some(libc::ENOSYS | libc::EINVAL)) {
            return Err(e);
        }
    }
    let aside = PathBuf::from(format!("{}-old", work.display()));
    std::fs::rename(target, &aside)?;
    std::fs::rename(work, target)?;
    Ok(Some(aside))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
        let mut out = Vec::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap().flatten() {
                let p = e.path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    let rel = p.strip_prefix(dir).unwrap().display().to_string();
                    out.push((rel, std::fs::read(&p).unwrap()));
                }
            }
        }
        out.sort();
        out
    }

    #[test]
    fn a_committed_set_replaces_the_previous_one_and_carries_what_it_did_not_write() {
        let scratch = tempfile::tempdir().unwrap();
        let target = scratch.path().join("out");
        std::fs::create_dir_all(target.join(".cache/runs")).unwrap();
        std::fs::write(target.join("results.json"), "old").unwrap();
        std::fs::write(target.join(".cache/runs/a.json"), "entry").unwrap();
        std::fs::write(target.join(".results.json.tmp-4242"), "half").unwrap();

        let set = OutputFolder::begin(&target, DEFAULT_WAIT).unwrap();
        // The previous set is there to read (the cache), and its files are
        // shared, not copied.
        assert_eq!(
            std::fs::read(set.dir().join(".cache/runs/a.json")).unwrap(),
            b"entry"
        );
        assert!(!set.dir().join(".results.json.tmp-4242").exists());
        super::super::write_atomic(&set.dir().join("results.json"), b"new").unwrap();
        // Until the commit, the target is the previous set, byte for byte.
        assert_eq!(std::fs::read(target.join("results.json")).unwrap(), b"old");
        let work = set.dir().to_path_buf();
        assert_eq!(set.commit().unwrap(), target);
        assert_eq!(
            tree(&target),
            vec![
                (".cache/runs/a.json".into(), b"entry".to_vec()),
                ("results.json".into(), b"new".to_vec()),
            ]
        );
        assert!(!work.exists(), "the previous set is removed");
    }

    #[test]
    fn a_set_dropped_without_commit_leaves_the_target_as_it_was() {
        let scratch = tempfile::tempdir().unwrap();
        let target = scratch.path().join("out");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("results.json"), "old").unwrap();
        let set = OutputFolder::begin(&target, DEFAULT_WAIT).unwrap();
        std::fs::write(set.dir().join("report.html"), "new").unwrap();
        let work = set.dir().to_path_buf();
        drop(set);
        assert!(!work.exists());
        assert_eq!(
            tree(&target),
            vec![("results.json".into(), b"old".to_vec())]
        );
    }

    #[test]
    fn a_dead_jobs_work_folder_is_swept_and_a_live_ones_is_kept() {
        let scratch = tempfile::tempdir().unwrap();
        let target = scratch.path().join("out");
        let dead = scratch.path().join(".out.servoid-99999999");
        let live = scratch.path().join(".out.servoid-99999998");
        let other = scratch.path().join(".out.servoid-notes");
        for d in [&dead, &live, &other] {
            std::fs::create_dir(d).unwrap();
        }
        let held = File::open(&live).unwrap();
        held.lock().unwrap();
        let set = OutputFolder::begin(&target, DEFAULT_WAIT).unwrap();
        assert!(!dead.exists());
        assert!(live.exists());
        assert!(other.exists(), "only servoid's own names are swept");
        set.commit().unwrap();
        assert!(target.is_dir());
    }

    #[test]
    fn a_previous_set_left_aside_by_a_killed_job_is_put_back_and_carried() {
        let scratch = tempfile::tempdir().unwrap();
        let target = scratch.path().join("out");
        let aside = scratch.path().join(".out.servoid-4242-old");
        std::fs::create_dir(&aside).unwrap();
        std::fs::write(aside.join("results.json"), "old").unwrap();
        let set = OutputFolder::begin(&target, DEFAULT_WAIT).unwrap();
        assert!(!aside.exists());
        assert_eq!(
            tree(&target),
            vec![("results.json".into(), b"old".to_vec())]
        );
        assert_eq!(
            std::fs::read(set.dir().join("results.json")).unwrap(),
            b"old"
        );
    }

    #[test]
    fn a_path_under_the_work_folder_is_named_under_the_target() {
        let scratch = tempfile::tempdir().unwrap();
        let target = scratch.path().join("out");
        let set = OutputFolder::begin(&target, DEFAULT_WAIT).unwrap();
        let inside = set.dir().join("figures/a.png");
        assert_eq!(set.final_path(&inside), target.join("figures/a.png"));
        assert_eq!(set.final_path(set.dir()), target);
        let e = WriteError::Io {
            path: inside,
            source: std::io::Error::other("full"),
        }
        .in_run("exp1");
        assert_eq!(
            set.relocate(e).to_string(),
            format!("run exp1: {}: full", target.join("figures/a.png").display())
        );
    }

    #[test]
    fn stale_names_are_only_servoids_temporaries() {
        assert!(stale(".results.json.tmp-123"));
        assert!(stale(".servoid-probe-9"));
        assert!(!stale("results.json.tmp-123"));
        assert!(!stale(".results.json.tmp-"));
        assert!(!stale(".notes.tmp-draft"));
    }
}
