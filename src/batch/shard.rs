//! A deterministic slice of a batch, from `--shard I/N` or a cluster's environment (Kubernetes
//! Indexed Jobs, Slurm arrays).

use super::BatchTake;
use serde::Serialize;

/// A slice of a batch: the takes whose index in relative-path order is `index` modulo `count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    pub fn new(index: usize, count: usize) -> Result<Shard, String> {
        if count == 0 {
            Err("the shard count must be at least 1".into())
        } else if index >= count {
            Err(format!(
                "shard index {index} is not below the count {count} (indexes start at 0)"
            ))
        } else {
            Ok(Shard { index, count })
        }
    }

    /// The shard from the environment, and the variables it came from: a Kubernetes Indexed Job's
    /// `JOB_COMPLETION_INDEX` (Kubernetes sets no count variable: `IMUBAKE_SHARD_COUNT` gives it,
    /// e.g. the Job's `completions`), or a Slurm array's `SLURM_ARRAY_TASK_ID` with
    /// `SLURM_ARRAY_TASK_COUNT` (index = (ID − `SLURM_ARRAY_TASK_MIN`) / `SLURM_ARRAY_TASK_STEP`;
    /// `IMUBAKE_SHARD_COUNT` overrides the count). `None` when neither index is set.
    pub fn from_env(
        var: impl Fn(&str) -> Option<String>,
    ) -> Result<Option<(Shard, &'static str)>, String> {
        let num = |name: &str| -> Result<Option<usize>, String> {
            match var(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => v
                    .trim()
                    .parse()
                    .map(Some)
                    .map_err(|_| format!("{name}=`{v}` is not a whole number ≥ 0")),
            }
        };
        let override_count = num("IMUBAKE_SHARD_COUNT")?;
        if let Some(index) = num("JOB_COMPLETION_INDEX")? {
            let count = override_count.ok_or(
                "JOB_COMPLETION_INDEX is set but Kubernetes gives no count: set IMUBAKE_SHARD_COUNT \
                 to the Job's completions, or pass --shard $(JOB_COMPLETION_INDEX)/N",
            )?;
            return Ok(Some((
                Shard::new(index, count)?,
                "JOB_COMPLETION_INDEX, IMUBAKE_SHARD_COUNT",
            )));
        }
        if let Some(id) = num("SLURM_ARRAY_TASK_ID")? {
            let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = num("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let count = match override_count {
                Some(c) => c,
                None => num("SLURM_ARRAY_TASK_COUNT")?.ok_or(
                    "SLURM_ARRAY_TASK_ID is set without SLURM_ARRAY_TASK_COUNT: set \
                     IMUBAKE_SHARD_COUNT or pass --shard I/N",
                )?,
            };
            let offset = id.checked_sub(min).ok_or(format!(
                "SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
            ))?;
            if offset % step != 0 {
                return Err(format!(
                    "SLURM_ARRAY_TASK_ID {id} is not on the array's step {step} from {min}"
                ));
            }
            return Ok(Some((
                Shard::new(offset / step, count)?,
                "SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT",
            )));
        }
        Ok(None)
    }

    /// The takes of this shard (`takes` sorted by relative path, as [`discover`] returns them).
    pub fn select(self, takes: Vec<BatchTake>) -> Vec<BatchTake> {
        let mut takes = takes;
        takes.sort_by(|a, b| a.rel.cmp(&b.rel));
        takes
            .into_iter()
            .enumerate()
            .filter(|(i, _)| i % self.count == self.index)
            .map(|(_, t)| t)
            .collect()
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}`: expected I/N, e.g. 0/4"))?;
        let parse = |v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{s}`: expected I/N with whole numbers, e.g. 0/4"))
        };
        Shard::new(parse(i)?, parse(n)?)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_from_the_environment() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                vars.iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(Shard::from_env(env(&[])).unwrap(), None);
        assert!(Shard::from_env(env(&[("JOB_COMPLETION_INDEX", "2")])).is_err());
        let (s, _) = Shard::from_env(env(&[
            ("JOB_COMPLETION_INDEX", "2"),
            ("IMUBAKE_SHARD_COUNT", "4"),
        ]))
        .unwrap()
        .unwrap();
        assert_eq!(s, Shard::new(2, 4).unwrap());
        let (s, _) = Shard::from_env(env(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_MIN", "5"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ]))
        .unwrap()
        .unwrap();
        assert_eq!(s, Shard::new(2, 3).unwrap());
        assert!(
            Shard::from_env(env(&[
                ("SLURM_ARRAY_TASK_ID", "3"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ]))
            .is_err(),
            "index 3 of 3"
        );
        assert_eq!("1/3".parse::<Shard>().unwrap(), Shard::new(1, 3).unwrap());
        assert!("3/3".parse::<Shard>().is_err());
        assert!("1/0".parse::<Shard>().is_err());
        assert!("x".parse::<Shard>().is_err());
    }
}
