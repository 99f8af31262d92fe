//! Orientation tracks as imubake CSV (`time_s,sensor,qw,qx,qy,qz`, `# world:` line): what
//! `imubake fuse` writes, and what `convert` reads back.

use crate::take::Track;
use crate::world::World;
use nalgebra::UnitQuaternion;
use std::io::{self, Write};

/// Writes `tracks` (`q_world_sensor` per sensor id) as one CSV in time order (ties in the given
/// order), after `comments` (each line prefixed with `# `) and the world line. Times with
/// microsecond precision, quaternion components with nine decimals (w first).
pub fn write(
    out: &mut dyn Write,
    world: World,
    comments: &[String],
    tracks: &[(&str, &Track<UnitQuaternion<f64>>)],
) -> io::Result<()> {
    if let Some((id, _)) = tracks.iter().find(|(id, _)| id.contains([',', '\n', '\r'])) {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "sensor id `{id}` holds a comma or a line break, which imubake CSV cannot carry"
            ),
        ));
    }
    for c in comments {
        for line in c.lines() {
            writeln!(out, "# {line}")?;
        }
    }
    writeln!(out, "# world: {world}")?;
    writeln!(out, "time_s,sensor,qw,qx,qy,qz")?;
    // A k-way merge by time: the tracks are each in time order already.
    let mut next = vec![0usize; tracks.len()];
    loop {
        let mut best: Option<(usize, f64)> = None;
        for (k, (_, track)) in tracks.iter().enumerate() {
            if let Some(&t) = track.times_s().get(next[k])
                && best.is_none_or(|(_, b)| t < b)
            {
                best = Some((k, t));
            }
        }
        let Some((k, t)) = best else {
            return Ok(());
        };
        let q = tracks[k].1.values()[next[k]];
        writeln!(
            out,
            "{t:.6},{},{:.9},{:.9},{:.9},{:.9}",
            tracks[k].0, q.w, q.i, q.j, q.k
        )?;
        next[k] += 1;
    }
}
