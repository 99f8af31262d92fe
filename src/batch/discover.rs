//! Finding the takes of files, folders and globs (`batch`, and `watch` on its inbox).
//!
//! What is a take, under a root folder (an input folder, a glob's base folder, the inbox):
//! - a regular file, or a session folder (x-IMU3, DOT, MTw) of regular files;
//! - not a hidden entry (`.*`), not the output folder, not a config, mapping or rig file
//!   (`imubake.yaml`, and any `.json`/`.yaml`/`.yml` that parses as one: logged at debug level);
//! - not a FIFO, socket or device (reading one can block forever or never end), not a symlink
//!   whose target resolves outside the root (unless `follow_symlinks`), not a broken symlink, and
//!   not a folder already being walked (a symlink cycle): each of these is skipped with a
//!   warning, and nothing of its target is read.
//!
//! Inputs named on the command line are taken as given (a symlink named there is followed), but a
//! named FIFO or device is still not a take: `convert` reads those.

use crate::convert::take_stem;
use crate::read::detect_format;
use globset::{GlobBuilder, GlobMatcher};
use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::fs;
use std::io;
use std::path::{Component, Path, PathBuf};

/// The config file an inbox (or any folder of one) may hold; never a take.
pub const FOLDER_CONFIG: &str = "imubake.yaml";

/// Config, mapping and rig files are at most this big; a larger file is not parsed as one.
const MAX_SETTINGS_FILE_BYTES: u64 = 4 << 20;

/// One take of a batch.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BatchTake {
    /// The file or session folder on disk.
    pub path: PathBuf,
    /// Its path relative to its input root, `/`-separated: the ledger's key and the order of
    /// sharding.
    pub rel: String,
    /// Where its outputs go, relative to the output root.
    pub out_dir: PathBuf,
    /// The name of its outputs.
    pub stem: String,
}

impl BatchTake {
    pub fn new(path: PathBuf, rel: &Path) -> BatchTake {
        let stem = take_stem(&path);
        BatchTake {
            rel: slash(rel),
            out_dir: rel.parent().map(Path::to_path_buf).unwrap_or_default(),
            stem,
            path,
        }
    }

    /// `<relative dir>/<stem>`: two takes with the same key would write the same outputs.
    pub fn output_key(&self) -> String {
        slash(&self.out_dir.join(&self.stem))
    }
}

/// A path's normal components joined with `/`.
pub fn slash(p: &Path) -> String {
    p.components()
        .filter_map(|c| match c {
            Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
            _ => None,
        })
        .collect::<Vec<_>>()
        .join("/")
}

#[derive(Debug, thiserror::Error)]
pub enum DiscoverError {
    #[error("{}: no such file or folder", .0.display())]
    Missing(PathBuf),
    #[error("`{0}` matches no file or folder")]
    NoMatch(String),
    #[error("`{pattern}`: {message}")]
    BadGlob { pattern: String, message: String },
    #[error("{}: cannot list: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error(
        "{} and {} would both write `{key}.*`: rename one, or convert them into different --out folders",
        .first.display(), .second.display()
    )]
    Collision {
        first: PathBuf,
        second: PathBuf,
        key: String,
    },
}

/// Why an entry is not a take.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum SkipReason {
    /// A FIFO, socket or device.
    NotRegular(&'static str),
    /// A symlink whose target resolves outside the root.
    OutsideRoot,
    BrokenSymlink,
    /// A folder already being walked, reached again through a symlink.
    SymlinkCycle,
    /// A session folder holding something that is not a take's material.
    SessionHolds {
        entry: String,
        why: &'static str,
    },
    /// A config, mapping or rig file (`"config"`, `"mapping"`, `"rig"`).
    SettingsFile(&'static str),
}

impl SkipReason {
    /// Whether the user should hear of it (settings files are skipped quietly).
    pub fn is_warning(&self) -> bool {
        !matches!(self, SkipReason::SettingsFile(_))
    }
}

impl fmt::Display for SkipReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SkipReason::NotRegular(kind) => {
                write!(f, "is a {kind}, not a regular file; not a take")
            }
            SkipReason::OutsideRoot => f.write_str(
                "is a symlink to something outside the folder; not followed (--follow-symlinks allows it)",
            ),
            SkipReason::BrokenSymlink => f.write_str("is a broken symlink"),
            SkipReason::SymlinkCycle => {
                f.write_str("leads back into a folder already being searched (a symlink cycle)")
            }
            SkipReason::SessionHolds { entry, why } => {
                write!(f, "is a session folder holding `{entry}`, {why}; not a take")
            }
            SkipReason::SettingsFile(kind) => write!(f, "is a {kind} file, not a take"),
        }
    }
}

/// An entry passed over, and why.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Skipped {
    pub path: PathBuf,
    pub reason: SkipReason,
}

/// The takes found, and what was passed over.
#[derive(Debug, Clone, Default)]
pub struct Discovery {
    /// Sorted by relative path.
    pub takes: Vec<BatchTake>,
    pub skipped: Vec<Skipped>,
}

#[derive(Debug, Clone, Copy, Default)]
pub struct DiscoverOptions<'a> {
    /// The output folder, when it may sit inside an input.
    pub exclude: Option<&'a Path>,
    /// Follow symlinks whose targets are outside the root.
    pub follow_symlinks: bool,
}

/// Whether a folder is itself one take (an x-IMU3 session, a DOT or MTw export).
pub fn is_session_folder(path: &Path) -> bool {
    path.is_dir() && detect_format(path).is_ok()
}

/// What kind of settings file `path` is, if it is one: `imubake.yaml` always; another
/// `.json`/`.yaml`/`.yml` when it parses as a config, a mapping, a rig or a packet layout.
pub fn settings_file_kind(path: &Path) -> Option<&'static str> {
    let name = path.file_name()?.to_string_lossy();
    if name == FOLDER_CONFIG {
        return Some("config");
    }
    let ext = path.extension()?.to_string_lossy().to_ascii_lowercase();
    if !matches!(ext.as_str(), "json" | "yaml" | "yml") {
        return None;
    }
    if fs::metadata(path).ok()?.len() > MAX_SETTINGS_FILE_BYTES {
        return None;
    }
    let text = fs::read_to_string(path).ok()?;
    if crate::config::Config::parse(&text).is_ok() {
        Some("config")
    } else if crate::mapping::parse_mapping(&text, path).is_ok() {
        Some("mapping")
    } else if crate::rig::file::parse_rig(&text, path).is_ok() {
        Some("rig")
    } else if crate::read::layout::Layout::parse(&text).is_ok() {
        Some("layout")
    } else {
        None
    }
}

/// The kind of a file-system entry that is neither a regular file nor a folder.
fn special_kind(meta: &fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "FIFO";
        } else if t.is_socket() {
            return "socket";
        } else if t.is_char_device() {
            return "character device";
        } else if t.is_block_device() {
            return "block device";
        }
    }
    let _ = meta;
    "special file"
}

/// Sorted non-hidden entries of a folder.
fn visible_entries(dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut entries = Vec::new();
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        if !entry.file_name().to_string_lossy().starts_with('.') {
            entries.push(entry.path());
        }
    }
    entries.sort();
    Ok(entries)
}

/// A walk under one root.
struct Walker<'a> {
    root: PathBuf,
    options: DiscoverOptions<'a>,
    exclude: Option<PathBuf>,
    /// Canonical folders on the current path (a folder met again is a cycle).
    ancestors: Vec<PathBuf>,
    /// For a glob: entries are takes only when their relative path matches.
    matcher: Option<GlobMatcher>,
    found: &'a mut Discovery,
}

/// What an entry resolves to.
enum Kind {
    File,
    Folder(PathBuf),
}

impl Walker<'_> {
    fn skip(&mut self, path: &Path, reason: SkipReason) {
        self.found.skipped.push(Skipped {
            path: path.to_path_buf(),
            reason,
        });
    }

    /// Classifies an entry met inside the root, applying the symlink and special-file rules.
    fn classify(&mut self, path: &Path) -> Option<Kind> {
        let meta = fs::symlink_metadata(path).ok()?;
        let meta = if meta.file_type().is_symlink() {
            let Ok(target) = fs::canonicalize(path) else {
                self.skip(path, SkipReason::BrokenSymlink);
                return None;
            };
            if !self.options.follow_symlinks && !target.starts_with(&self.root) {
                self.skip(path, SkipReason::OutsideRoot);
                return None;
            }
            fs::metadata(path).ok()?
        } else {
            meta
        };
        if meta.is_dir() {
            let canonical = fs::canonicalize(path).ok()?;
            if self.exclude.as_ref() == Some(&canonical) {
                return None;
            }
            Some(Kind::Folder(canonical))
        } else if meta.is_file() {
            Some(Kind::File)
        } else {
            self.skip(path, SkipReason::NotRegular(special_kind(&meta)));
            None
        }
    }

    fn matches(&self, rel: &Path) -> bool {
        self.matcher.as_ref().is_none_or(|m| m.is_match(rel))
    }

    fn entry(&mut self, path: PathBuf, rel: PathBuf) -> Result<(), DiscoverError> {
        match self.classify(&path) {
            None => Ok(()),
            Some(Kind::File) => {
                if self.matches(&rel) {
                    self.file(path, &rel);
                }
                Ok(())
            }
            Some(Kind::Folder(canonical)) => {
                if self.matches(&rel) {
                    // A matched folder is taken whole, like a folder input.
                    let matcher = self.matcher.take();
                    let result = self.folder(path, rel, canonical);
                    self.matcher = matcher;
                    result
                } else if is_session_folder(&path) {
                    // Session folders are takes, not containers of takes.
                    Ok(())
                } else {
                    self.walk(&path, &rel, canonical)
                }
            }
        }
    }

    fn file(&mut self, path: PathBuf, rel: &Path) {
        match settings_file_kind(&path) {
            Some(kind) => self.skip(&path, SkipReason::SettingsFile(kind)),
            None => self.found.takes.push(BatchTake::new(path, rel)),
        }
    }

    fn folder(
        &mut self,
        path: PathBuf,
        rel: PathBuf,
        canonical: PathBuf,
    ) -> Result<(), DiscoverError> {
        if self.ancestors.contains(&canonical) {
            self.skip(&path, SkipReason::SymlinkCycle);
            return Ok(());
        }
        if is_session_folder(&path) {
            match self.session_problem(&path) {
                Some(reason) => self.skip(&path, reason),
                None => self.found.takes.push(BatchTake::new(path, &rel)),
            }
            return Ok(());
        }
        self.walk(&path, &rel, canonical)
    }

    fn walk(&mut self, dir: &Path, rel: &Path, canonical: PathBuf) -> Result<(), DiscoverError> {
        if self.ancestors.contains(&canonical) {
            self.skip(dir, SkipReason::SymlinkCycle);
            return Ok(());
        }
        let entries = visible_entries(dir).map_err(|source| DiscoverError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
        self.ancestors.push(canonical);
        for path in entries {
            let name = path.file_name().map(PathBuf::from).unwrap_or_default();
            let result = self.entry(path, rel.join(name));
            if result.is_err() {
                self.ancestors.pop();
                return result;
            }
        }
        self.ancestors.pop();
        Ok(())
    }

    /// Why a session folder is not a take: it holds a special file or a symlink leaving the root.
    fn session_problem(&self, dir: &Path) -> Option<SkipReason> {
        fn scan(walker: &Walker<'_>, top: &Path, dir: &Path, depth: usize) -> Option<SkipReason> {
            let entries = visible_entries(dir).ok()?;
            for path in entries {
                let entry = || {
                    path.strip_prefix(top)
                        .map(slash)
                        .unwrap_or_else(|_| path.display().to_string())
                };
                let meta = fs::symlink_metadata(&path).ok()?;
                if meta.file_type().is_symlink() {
                    let outside = match fs::canonicalize(&path) {
                        Ok(target) => !target.starts_with(&walker.root),
                        Err(_) => {
                            return Some(SkipReason::SessionHolds {
                                entry: entry(),
                                why: "a broken symlink",
                            });
                        }
                    };
                    if outside && !walker.options.follow_symlinks {
                        return Some(SkipReason::SessionHolds {
                            entry: entry(),
                            why: "a symlink to something outside the folder (--follow-symlinks allows it)",
                        });
                    }
                }
                let meta = fs::metadata(&path).ok()?;
                if meta.is_dir() {
                    if depth < 4
                        && let Some(r) = scan(walker, top, &path, depth + 1)
                    {
                        return Some(r);
                    }
                } else if !meta.is_file() {
                    return Some(SkipReason::SessionHolds {
                        entry: entry(),
                        why: special_kind(&meta),
                    });
                }
            }
            None
        }
        scan(self, dir, dir, 0)
    }
}

/// The folder before the first wildcard component, and the pattern from there on.
fn split_glob(pattern: &Path) -> (PathBuf, String) {
    let mut base = PathBuf::new();
    let mut rest = Vec::new();
    for c in pattern.components() {
        let s = c.as_os_str().to_string_lossy();
        if rest.is_empty() && !s.contains(['*', '?', '[', '{']) {
            base.push(c.as_os_str());
        } else {
            rest.push(s.into_owned());
        }
    }
    if base.as_os_str().is_empty() {
        base = PathBuf::from(".");
    }
    (base, rest.join("/"))
}

fn is_glob(input: &Path) -> bool {
    !input.exists() && input.to_string_lossy().contains(['*', '?'])
}

/// The takes of `inputs`: a file is a take (relative to its folder); a session folder is a take
/// (relative to its parent); any other folder contributes its files and session sub-folders,
/// recursively, relative to itself; an input with `*`, `?` or `**` that is not an existing path is
/// a glob (globset syntax, `*` within a name, `**` across folders), its matches relative to the
/// folder before its first wildcard (matched folders expand like folder inputs). The module docs
/// say what is passed over. A take named twice counts once. Sorted by relative path; two takes
/// with the same outputs are an error.
pub fn discover(
    inputs: &[PathBuf],
    options: DiscoverOptions<'_>,
) -> Result<Discovery, DiscoverError> {
    let exclude = options.exclude.and_then(|p| p.canonicalize().ok());
    let mut found = Discovery::default();
    for input in inputs {
        if is_glob(input) {
            let (base, pattern) = split_glob(input);
            let matcher = GlobBuilder::new(&pattern)
                .literal_separator(true)
                .build()
                .map_err(|e| DiscoverError::BadGlob {
                    pattern: input.to_string_lossy().into_owned(),
                    message: e.kind().to_string(),
                })?
                .compile_matcher();
            let before = found.takes.len();
            if let Ok(root) = base.canonicalize() {
                let mut walker = Walker {
                    root: root.clone(),
                    options,
                    exclude: exclude.clone(),
                    ancestors: Vec::new(),
                    matcher: Some(matcher),
                    found: &mut found,
                };
                walker.walk(&base, Path::new(""), root)?;
            }
            if found.takes.len() == before {
                return Err(DiscoverError::NoMatch(input.to_string_lossy().into_owned()));
            }
            continue;
        }
        let meta = fs::metadata(input).map_err(|_| DiscoverError::Missing(input.clone()))?;
        let root = input
            .canonicalize()
            .map_err(|_| DiscoverError::Missing(input.clone()))?;
        let mut walker = Walker {
            root: root.clone(),
            options,
            exclude: exclude.clone(),
            ancestors: Vec::new(),
            matcher: None,
            found: &mut found,
        };
        if meta.is_dir() {
            if is_session_folder(input) {
                let rel = PathBuf::from(take_stem(input));
                match walker.session_problem(input) {
                    Some(reason) => walker.skip(input, reason),
                    None => walker.found.takes.push(BatchTake::new(input.clone(), &rel)),
                }
            } else {
                walker.walk(input, Path::new(""), root)?;
            }
        } else if meta.is_file() {
            let name = input.file_name().map(PathBuf::from).unwrap_or_default();
            walker.file(input.clone(), &name);
        } else {
            walker.skip(input, SkipReason::NotRegular(special_kind(&meta)));
        }
    }
    // The same take named twice (a folder and a glob inside it, a symlink beside its target)
    // counts once, under its own name rather than a symlink's.
    let is_link = |t: &BatchTake| fs::symlink_metadata(&t.path).is_ok_and(|m| m.is_symlink());
    found.takes.sort_by_key(is_link);
    let mut seen = HashSet::new();
    found
        .takes
        .retain(|t| seen.insert(t.path.canonicalize().unwrap_or_else(|_| t.path.clone())));
    found.takes.sort_by(|a, b| a.rel.cmp(&b.rel));
    let mut keys: BTreeMap<String, &BatchTake> = BTreeMap::new();
    for t in &found.takes {
        if let Some(first) = keys.insert(t.output_key(), t) {
            return Err(DiscoverError::Collision {
                first: first.path.clone(),
                second: t.path.clone(),
                key: t.output_key(),
            });
        }
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rels(d: &Discovery) -> Vec<&str> {
        d.takes.iter().map(|t| t.rel.as_str()).collect()
    }

    fn reasons(d: &Discovery) -> Vec<(String, SkipReason)> {
        let mut v: Vec<_> = d
            .skipped
            .iter()
            .map(|s| {
                (
                    s.path.file_name().unwrap().to_string_lossy().into_owned(),
                    s.reason.clone(),
                )
            })
            .collect();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    }

    #[test]
    #[cfg(unix)]
    fn only_regular_files_inside_the_root_are_takes() {
        let tmp = tempfile::tempdir().unwrap();
        let (inbox, outside) = (tmp.path().join("in"), tmp.path().join("outside"));
        fs::create_dir_all(inbox.join("sub")).unwrap();
        fs::create_dir_all(&outside).unwrap();
        fs::write(outside.join("secret.csv"), "secret").unwrap();
        fs::write(inbox.join("good.csv"), "x").unwrap();
        fs::write(inbox.join("sub/inner.csv"), "x").unwrap();
        std::os::unix::fs::symlink("/dev/zero", inbox.join("z.csv")).unwrap();
        std::os::unix::fs::symlink(outside.join("secret.csv"), inbox.join("leak.csv")).unwrap();
        std::os::unix::fs::symlink(inbox.join("good.csv"), inbox.join("alias.csv")).unwrap();
        std::os::unix::fs::symlink(inbox.join("missing"), inbox.join("broken.csv")).unwrap();
        std::os::unix::fs::symlink("..", inbox.join("sub/up")).unwrap();
        let fifo = inbox.join("p.csv");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.is_ok_and(|s| s.success()), "mkfifo");
        fs::write(inbox.join(FOLDER_CONFIG), "mapping: m.json\n").unwrap();

        let d = discover(std::slice::from_ref(&inbox), DiscoverOptions::default()).unwrap();
        // A symlink inside the root is followed; it is the same take twice as `good.csv`, so its
        // outputs would collide: the alias names it once (dedup by canonical path).
        assert_eq!(rels(&d), ["good.csv", "sub/inner.csv"]);
        assert_eq!(
            reasons(&d),
            [
                ("broken.csv".into(), SkipReason::BrokenSymlink),
                (FOLDER_CONFIG.into(), SkipReason::SettingsFile("config")),
                ("leak.csv".into(), SkipReason::OutsideRoot),
                ("p.csv".into(), SkipReason::NotRegular("FIFO")),
                ("up".into(), SkipReason::SymlinkCycle),
                ("z.csv".into(), SkipReason::OutsideRoot),
            ]
        );
        // --follow-symlinks reads the outside file, and still refuses the device.
        let follow = DiscoverOptions {
            follow_symlinks: true,
            ..Default::default()
        };
        let d = discover(std::slice::from_ref(&inbox), follow).unwrap();
        assert_eq!(rels(&d), ["good.csv", "leak.csv", "sub/inner.csv"]);
        assert!(
            reasons(&d).contains(&("z.csv".into(), SkipReason::NotRegular("character device")))
        );
        assert!(reasons(&d).contains(&("up".into(), SkipReason::SymlinkCycle)));
    }

    #[test]
    fn settings_files_are_recognised_by_content() {
        let tmp = tempfile::tempdir().unwrap();
        let p = |n: &str| tmp.path().join(n);
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        fs::copy(
            root.join("mappings/paper000_16imu_mixamo.json"),
            p("m.json"),
        )
        .unwrap();
        fs::copy(root.join("rigs/sou12.yaml"), p("r.yaml")).unwrap();
        fs::copy(root.join("layouts/esp32_struct.yaml"), p("suit.yaml")).unwrap();
        fs::write(p("c.yml"), "fps: 60\nsmoothing: none\n").unwrap();
        fs::write(p("notes.json"), "{\"hello\": 1}").unwrap();
        fs::write(p("walk.csv"), "time_s,sensor\n").unwrap();
        assert_eq!(settings_file_kind(&p("m.json")), Some("mapping"));
        assert_eq!(settings_file_kind(&p("r.yaml")), Some("rig"));
        assert_eq!(settings_file_kind(&p("c.yml")), Some("config"));
        assert_eq!(settings_file_kind(&p("suit.yaml")), Some("layout"));
        assert_eq!(settings_file_kind(&p("notes.json")), None);
        assert_eq!(settings_file_kind(&p("walk.csv")), None);
    }

    #[test]
    fn globs_match_within_names_and_across_folders() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("lib");
        for f in [
            "a.log",
            "b.csv",
            "day1/c.log",
            "day1/deep/d.log",
            "day2/e.log",
        ] {
            let p = root.join(f);
            fs::create_dir_all(p.parent().unwrap()).unwrap();
            fs::write(p, "x").unwrap();
        }
        let find = |pattern: &str| {
            let d = discover(&[root.join(pattern)], DiscoverOptions::default()).unwrap();
            rels(&d).iter().map(|s| s.to_string()).collect::<Vec<_>>()
        };
        assert_eq!(find("*.log"), ["a.log"]);
        assert_eq!(
            find("**/*.log"),
            ["a.log", "day1/c.log", "day1/deep/d.log", "day2/e.log"]
        );
        assert_eq!(find("day*/*.log"), ["day1/c.log", "day2/e.log"]);
        // A matched folder is taken whole.
        assert_eq!(find("day1"), ["c.log", "deep/d.log"]);
        assert_eq!(
            find("day?"),
            ["day1/c.log", "day1/deep/d.log", "day2/e.log"]
        );
        assert!(matches!(
            discover(&[root.join("*.nothing")], DiscoverOptions::default()),
            Err(DiscoverError::NoMatch(_))
        ));
    }
}
