//! Where the tool writes, so that an output never destroys an input and a command writes
//! all its outputs or none.
//!
//! A command first lists its inputs and outputs in an [`OutputPlan`], which checks every
//! output before any work is done: its directory exists, it is not a directory, it is not
//! the same file as an input or as another output (compared by device and inode when the
//! file exists, by canonical directory and name when it does not), and a figure ends in
//! `.png` or `.svg`. The command then writes each output to its *staging* file, a
//! temporary file beside the destination that keeps its extension
//! (`.NAME.tmp-PID.EXT`), and [`OutputPlan::commit`] moves every staged file into place
//! once all are written.
//!
//! - A symbolic link is followed: its target is replaced, the link stays.
//! - A special file (a FIFO, a device such as `/dev/null`) is written through: the staged
//!   bytes are copied into it; it is never renamed over.
//! - Staging files are removed when a command fails, when the plan is dropped without a
//!   commit, and on Ctrl-C (the process then exits with status 130).

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, Once};

/// What an output is, for the checks its name must pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Any file (CSV, JSON, a CAN log).
    File,
    /// A figure: `.png` or `.svg`.
    Figure,
}

/// Why an output was refused.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output is the same file as an input.
    #[error("{output}: is the input {input}: refusing to overwrite an input")]
    IsInput {
        /// The output as given.
        output: String,
        /// The input as given.
        input: String,
    },
    /// Two outputs are the same file.
    #[error("{0}: given for two outputs: each output needs its own file")]
    Twice(String),
    /// The output's directory does not exist or is not a directory.
    #[error("{path}: the directory {dir} does not exist")]
    NoDirectory {
        /// The output as given.
        path: String,
        /// Its directory.
        dir: String,
    },
    /// The output names a directory.
    #[error("{0}: is a directory, not a file")]
    IsDirectory(String),
    /// The output has no file name (`..`, `/`).
    #[error("{0}: not a file name")]
    NotAFile(String),
    /// A figure's name ends in neither `.png` nor `.svg`.
    #[error("{0}: figures are written as .png or .svg")]
    FigureFormat(String),
    /// Reading, writing or moving a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        source: io::Error,
    },
}

fn io_error(path: &Path) -> impl FnOnce(io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Where a staged output ends up.
#[derive(Debug)]
enum Destination {
    /// A regular file (or one to create): the staged file is renamed over it.
    Replace(PathBuf),
    /// A special file: the staged bytes are copied into it.
    WriteThrough(PathBuf),
}

#[derive(Debug)]
struct Planned {
    destination: Destination,
    staging: PathBuf,
}

/// A command's checked outputs and their staging files.
#[derive(Debug)]
pub struct OutputPlan {
    planned: Vec<Planned>,
    committed: bool,
}

/// A file's identity: device and inode when it exists, else its canonical directory and
/// its name.
#[derive(Debug, PartialEq, Eq)]
enum Identity {
    Inode(u64, u64),
    Path(PathBuf),
}

fn identity(path: &Path) -> Option<Identity> {
    use std::os::unix::fs::MetadataExt;
    if let Ok(m) = fs::metadata(path) {
        return Some(Identity::Inode(m.dev(), m.ino()));
    }
    let dir = directory_of(path);
    let name = path.file_name()?;
    Some(Identity::Path(fs::canonicalize(dir).ok()?.join(name)))
}

/// The directory a path's file is in (`.` for a bare name).
fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

impl OutputPlan {
    /// Checks `outputs` (path and kind) against each other and against `inputs`, before
    /// any work; nothing is created yet.
    pub fn new(inputs: &[&Path], outputs: &[(&Path, Kind)]) -> Result<OutputPlan, OutputError> {
        let shown = |p: &Path| p.display().to_string();
        let mut seen: Vec<Identity> = Vec::new();
        let mut planned = Vec::new();
        for &(path, kind) in outputs {
            let Some(name) = path.file_name() else {
                return Err(OutputError::NotAFile(shown(path)));
            };
            if kind == Kind::Figure
                && !matches!(
                    path.extension().and_then(|e| e.to_str()),
                    Some("png" | "svg")
                )
            {
                return Err(OutputError::FigureFormat(shown(path)));
            }
            let dir = directory_of(path);
            if !dir.is_dir() {
                return Err(OutputError::NoDirectory {
                    path: shown(path),
                    dir: shown(dir),
                });
            }
            let meta = fs::metadata(path).ok();
            if meta.as_ref().is_some_and(fs::Metadata::is_dir) {
                return Err(OutputError::IsDirectory(shown(path)));
            }
            let id = identity(path).ok_or_else(|| OutputError::NotAFile(shown(path)))?;
            for input in inputs {
                if identity(input).as_ref() == Some(&id) {
                    return Err(OutputError::IsInput {
                        output: shown(path),
                        input: shown(input),
                    });
                }
            }
            if seen.contains(&id) {
                return Err(OutputError::Twice(shown(path)));
            }
            seen.push(id);
            let special = meta.as_ref().is_some_and(|m| !m.is_file());
            let mut staged = std::ffi::OsString::from(".");
            staged.push(path.file_stem().unwrap_or(name));
            staged.push(format!(".tmp-{}", std::process::id()));
            if let Some(ext) = path.extension() {
                staged.push(".");
                staged.push(ext);
            }
            let (destination, staging) = if special {
                (
                    Destination::WriteThrough(path.to_path_buf()),
                    std::env::temp_dir().join(staged),
                )
            } else {
                // A link is followed: its target is what gets replaced.
                let real = fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
                let staging = directory_of(&real).join(staged);
                (Destination::Replace(real), staging)
            };
            planned.push(Planned {
                destination,
                staging,
            });
        }
        let plan = OutputPlan {
            planned,
            committed: false,
        };
        for p in &plan.planned {
            register(&p.staging);
        }
        Ok(plan)
    }

    /// Where the command writes output `k` (in the order given to [`OutputPlan::new`]).
    pub fn staging(&self, k: usize) -> &Path {
        self.planned.get(k).map_or(Path::new(""), |p| &p.staging)
    }

    /// Writes `bytes` as output `k`'s staged content.
    pub fn write(&self, k: usize, bytes: &[u8]) -> Result<(), OutputError> {
        let path = self.staging(k);
        fs::write(path, bytes).map_err(io_error(path))
    }

    /// Moves every staged output into place. Each must have been written.
    pub fn commit(mut self) -> Result<(), OutputError> {
        for p in &self.planned {
            let f = fs::File::open(&p.staging).map_err(io_error(&p.staging))?;
            f.sync_all().map_err(io_error(&p.staging))?;
        }
        for p in &self.planned {
            match &p.destination {
                Destination::Replace(to) => {
                    fs::rename(&p.staging, to).map_err(io_error(to))?;
                }
                Destination::WriteThrough(to) => {
                    let mut from = fs::File::open(&p.staging).map_err(io_error(&p.staging))?;
                    let mut into = fs::OpenOptions::new()
                        .write(true)
                        .open(to)
                        .map_err(io_error(to))?;
                    io::copy(&mut from, &mut into).map_err(io_error(to))?;
                    let _ = fs::remove_file(&p.staging);
                }
            }
            unregister(&p.staging);
        }
        self.committed = true;
        Ok(())
    }
}

impl Drop for OutputPlan {
    fn drop(&mut self) {
        for p in &self.planned {
            if !self.committed {
                let _ = fs::remove_file(&p.staging);
            }
            unregister(&p.staging);
        }
    }
}

/// Staging files to remove on Ctrl-C.
static STAGED: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn register(path: &Path) {
    static HANDLER: Once = Once::new();
    HANDLER.call_once(|| {
        // Without a handler (another one was set), Ctrl-C only leaves staging files behind.
        let _ = ctrlc::set_handler(|| {
            if let Ok(staged) = STAGED.lock() {
                for p in staged.iter() {
                    let _ = fs::remove_file(p);
                }
            }
            std::process::exit(130);
        });
    });
    if let Ok(mut staged) = STAGED.lock() {
        staged.push(path.to_path_buf());
    }
}

fn unregister(path: &Path) {
    if let Ok(mut staged) = STAGED.lock() {
        staged.retain(|p| p != path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh directory, removed with everything in it when the guard is dropped.
    fn scratch(name: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("fingertip-output-{name}-"))
            .tempdir()
            .expect("scratch")
    }

    fn refused(inputs: &[&Path], outputs: &[(&Path, Kind)], words: &[&str]) {
        let e = OutputPlan::new(inputs, outputs)
            .expect_err("refused")
            .to_string();
        for w in words {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
    }

    /// Every way an output can name an input or another output is refused, and nothing is
    /// written: the same path, another spelling (`./`, `dir/../`), a hard link, a symbolic
    /// link to it, for inputs and between outputs.
    #[test]
    fn an_output_that_is_an_input_or_another_output_is_refused() {
        let tmp = scratch("same");
        let dir = tmp.path();
        let input = dir.join("run.csv");
        fs::write(&input, "data").expect("write");
        let hard = dir.join("hard.csv");
        fs::hard_link(&input, &hard).expect("link");
        let soft = dir.join("soft.csv");
        std::os::unix::fs::symlink(&input, &soft).expect("symlink");
        let dotted = dir.join(".").join("run.csv");
        let sub = dir.join("sub");
        fs::create_dir_all(&sub).expect("sub");
        let around = sub.join("..").join("run.csv");
        for same in [&input, &hard, &soft, &dotted, &around] {
            refused(
                &[&input],
                &[(same, Kind::File)],
                &["refusing to overwrite an input"],
            );
        }
        let out = dir.join("new.csv");
        let out_again = dir.join(".").join("new.csv");
        refused(
            &[&input],
            &[(&out, Kind::File), (&out_again, Kind::File)],
            &["new.csv", "two outputs"],
        );
        assert_eq!(fs::read_to_string(&input).expect("read"), "data");
        assert!(!out.exists());
        let staged: Vec<_> = fs::read_dir(dir)
            .expect("dir")
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(staged.is_empty(), "{staged:?}");
    }

    #[test]
    fn bad_places_and_names_are_refused_before_any_work() {
        let tmp = scratch("bad");
        let dir = tmp.path();
        refused(
            &[],
            &[(&dir.join("none").join("x.csv"), Kind::File)],
            &["does not exist"],
        );
        refused(&[], &[(dir, Kind::File)], &["is a directory"]);
        refused(
            &[],
            &[(&dir.join("b.jpg"), Kind::Figure)],
            &["b.jpg", ".png or .svg"],
        );
        refused(&[], &[(Path::new("/"), Kind::File)], &["not a file name"]);
        assert!(OutputPlan::new(&[], &[(&dir.join("f.svg"), Kind::Figure)]).is_ok());
    }

    /// All or none: outputs appear only at the commit; a plan dropped without one leaves
    /// neither outputs nor staging files. A link's target is replaced and the link stays;
    /// a special file is written through, not replaced.
    #[test]
    fn outputs_appear_together_at_the_commit() {
        let tmp = scratch("commit");
        let dir = tmp.path();
        let a = dir.join("a.csv");
        let b = dir.join("b.json");
        let plan = OutputPlan::new(&[], &[(&a, Kind::File), (&b, Kind::File)]).expect("plan");
        plan.write(0, b"a").expect("write");
        assert!(!a.exists(), "nothing before the commit");
        drop(plan);
        let leftovers: Vec<_> = fs::read_dir(dir).expect("dir").collect();
        assert!(leftovers.is_empty(), "{leftovers:?}");

        let plan = OutputPlan::new(&[], &[(&a, Kind::File), (&b, Kind::File)]).expect("plan");
        assert_eq!(
            plan.staging(0).extension().and_then(|e| e.to_str()),
            Some("csv")
        );
        plan.write(0, b"a").expect("write");
        plan.write(1, b"b").expect("write");
        plan.commit().expect("commit");
        assert_eq!(fs::read_to_string(&a).expect("a"), "a");
        assert_eq!(fs::read_to_string(&b).expect("b"), "b");

        let target = dir.join("target.csv");
        fs::write(&target, "old").expect("write");
        let link = dir.join("link.csv");
        std::os::unix::fs::symlink(&target, &link).expect("symlink");
        let plan = OutputPlan::new(&[], &[(&link, Kind::File)]).expect("plan");
        plan.write(0, b"new").expect("write");
        plan.commit().expect("commit");
        assert!(
            fs::symlink_metadata(&link)
                .expect("link")
                .file_type()
                .is_symlink()
        );
        assert_eq!(fs::read_to_string(&target).expect("target"), "new");

        let null = Path::new("/dev/null");
        let plan = OutputPlan::new(&[], &[(null, Kind::File)]).expect("plan");
        plan.write(0, b"gone").expect("write");
        plan.commit().expect("commit");
        let m = fs::symlink_metadata(null).expect("null");
        assert!(!m.is_file(), "/dev/null is still a device");
    }
}
