//! Splitting one job into `N` shards that separate processes (tasks of a Slurm job array,
//! or any other launcher) run independently: `--shard I/N` (0-based) or `--shard slurm`.
//!
//! The split is contiguous blocks of the ordered work items (frames of a path after
//! `--frames`, cameras of an eval split, points of a bench sweep): shard `i` of `n` over
//! `len` items takes `[i * len / n, (i + 1) * len / n)`, so shard sizes differ by at most
//! one, every item is taken exactly once, and the split depends only on `len`, never on
//! which files exist (a resumed shard takes the same frames). Blocks rather than
//! round-robin: neighbouring frames of a path cost about the same, so blocks balance as
//! well, and a shard's frames are one range of file numbers (easy to read in a log, to
//! check and to re-run with `--frames`).

use std::ops::Range;

/// One shard: `index` of `count` (0-based, `index < count`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, 0-based.
    pub index: usize,
    /// How many shards split the job.
    pub count: usize,
}

/// What `--shard` says: a fixed `I/N`, or the Slurm array task's environment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardSpec {
    /// `I/N`.
    Fixed(Shard),
    /// `slurm`: `SLURM_ARRAY_TASK_ID` / `_COUNT` / `_MIN` (and `_STEP`).
    Slurm,
}

impl std::str::FromStr for ShardSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.trim().eq_ignore_ascii_case("slurm") {
            return Ok(ShardSpec::Slurm);
        }
        let bad =
            || format!("--shard {s:?}: expected I/N (shard I of N, 0-based, e.g. 0/4) or slurm");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        Shard::new(index, count)
            .map(ShardSpec::Fixed)
            .map_err(|e| format!("--shard {s}: {e}"))
    }
}

impl Shard {
    /// Shard `index` of `count`; an error sentence when `count` is 0 or `index >= count`.
    pub fn new(index: usize, count: usize) -> Result<Shard, String> {
        if count == 0 {
            return Err("the number of shards must be at least 1".into());
        }
        if index >= count {
            return Err(format!(
                "shard {index} does not exist: shards are numbered 0 to {} (0-based)",
                count - 1
            ));
        }
        Ok(Shard { index, count })
    }

    /// The positions this shard takes of `len` ordered items: a contiguous block.
    pub fn range(&self, len: usize) -> Range<usize> {
        // u128: no overflow for any usize len and count.
        let at = |i: usize| (i as u128 * len as u128 / self.count as u128) as usize;
        at(self.index)..at(self.index + 1)
    }

    /// This shard's items of `items`, in order.
    pub fn take<T>(&self, items: Vec<T>) -> Vec<T> {
        let r = self.range(items.len());
        items.into_iter().skip(r.start).take(r.len()).collect()
    }

    /// `path` with `.shard-I-of-N` before its extension (`report.json` gives
    /// `report.shard-2-of-4.json`): the file of this shard, so shards never write the
    /// same file.
    pub fn file_name(&self, path: &std::path::Path) -> std::path::PathBuf {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let name = match path.extension() {
            Some(ext) => format!("{stem}.{}.{}", self.tag(), ext.to_string_lossy()),
            None => format!("{stem}.{}", self.tag()),
        };
        path.with_file_name(name)
    }

    /// `shard-I-of-N`.
    pub fn tag(&self) -> String {
        format!("shard-{}-of-{}", self.index, self.count)
    }

    /// Reads a [`Shard::tag`] back (`shard-2-of-4`).
    pub fn parse_tag(tag: &str) -> Option<Shard> {
        let (i, n) = tag.strip_prefix("shard-")?.split_once("-of-")?;
        Shard::new(i.parse().ok()?, n.parse().ok()?).ok()
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "shard {}/{}", self.index, self.count)
    }
}

impl ShardSpec {
    /// The shard, reading the Slurm array variables through `env` for `slurm`.
    /// A missing or malformed variable, or an array whose task ids are not evenly spaced
    /// (`--array=0,3,7`), is an error sentence.
    pub fn resolve(&self, env: impl Fn(&str) -> Option<String>) -> Result<Shard, String> {
        if let ShardSpec::Fixed(shard) = *self {
            return Ok(shard);
        }
        let var = |name: &str| -> Result<Option<usize>, String> {
            match env(name) {
                None => Ok(None),
                Some(v) => v
                    .trim()
                    .parse()
                    .map(Some)
                    .map_err(|_| format!("--shard slurm: {name}={v:?} is not a task number")),
            }
        };
        let (Some(id), Some(count)) = (var("SLURM_ARRAY_TASK_ID")?, var("SLURM_ARRAY_TASK_COUNT")?)
        else {
            return Err(
                "--shard slurm: SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT are not set: this is not a task of a Slurm job array (submit with sbatch --array=0-N) or give --shard I/N"
                    .into(),
            );
        };
        let min = var("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
        let step = var("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
        let max = var("SLURM_ARRAY_TASK_MAX")?;
        let spaced = id >= min
            && (id - min) % step == 0
            && max.map_or(true, |max| max >= min && (max - min) / step + 1 == count);
        if !spaced {
            return Err(format!(
                "--shard slurm: task {id} of an array of {count} with ids from {min}{} is not one of evenly spaced ids; submit with --array=A-B or A-B:STEP, or give --shard I/N",
                max.map_or(String::new(), |m| format!(" to {m}"))
            ));
        }
        Shard::new((id - min) / step, count).map_err(|e| format!("--shard slurm: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_cover_every_item_once_and_differ_by_at_most_one() {
        for len in [0, 1, 3, 4, 7, 24, 1000] {
            for count in [1, 2, 3, 4, 5, 8, 50] {
                let ranges: Vec<Range<usize>> = (0..count)
                    .map(|i| Shard::new(i, count).unwrap().range(len))
                    .collect();
                let mut next = 0;
                for r in &ranges {
                    assert_eq!(r.start, next, "{len} in {count}: {ranges:?}");
                    next = r.end;
                }
                assert_eq!(next, len);
                let sizes: Vec<usize> = ranges.iter().map(|r| r.len()).collect();
                let (lo, hi) = (sizes.iter().min().unwrap(), sizes.iter().max().unwrap());
                assert!(hi - lo <= 1, "{len} in {count}: {sizes:?}");
            }
        }
        assert_eq!(Shard::new(1, 4).unwrap().take((0..10).collect()), [2, 3, 4]);
    }

    #[test]
    fn specs_parse_and_bad_ones_say_why() {
        let fixed = |i, n| ShardSpec::Fixed(Shard { index: i, count: n });
        assert_eq!("0/4".parse(), Ok(fixed(0, 4)));
        assert_eq!(" 3 / 4 ".parse(), Ok(fixed(3, 4)));
        assert_eq!("slurm".parse(), Ok(ShardSpec::Slurm));
        let e = "4/4".parse::<ShardSpec>().unwrap_err();
        assert!(e.contains("shards are numbered 0 to 3"), "{e}");
        let e = "1/0".parse::<ShardSpec>().unwrap_err();
        assert!(e.contains("at least 1"), "{e}");
        for bad in ["", "1", "a/4", "1/4/5", "-1/4", "1/b"] {
            let e = bad.parse::<ShardSpec>().unwrap_err();
            assert!(e.contains("expected I/N"), "{bad}: {e}");
        }
    }

    #[test]
    fn slurm_array_variables_give_the_shard() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                vars.iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        let s = ShardSpec::Slurm;
        let got = s.resolve(env(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_MAX", "3"),
        ]));
        assert_eq!(got, Ok(Shard { index: 2, count: 4 }));
        // --array=1-4 and --array=10-40:10 are shards 0..3 too.
        let got = s.resolve(env(&[
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
        ]));
        assert_eq!(got, Ok(Shard { index: 3, count: 4 }));
        let got = s.resolve(env(&[
            ("SLURM_ARRAY_TASK_ID", "30"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "10"),
            ("SLURM_ARRAY_TASK_MAX", "40"),
            ("SLURM_ARRAY_TASK_STEP", "10"),
        ]));
        assert_eq!(got, Ok(Shard { index: 2, count: 4 }));
        let e = s.resolve(env(&[])).unwrap_err();
        assert!(e.contains("not a task of a Slurm job array"), "{e}");
        // A job that is not an array has SLURM_JOB_ID but no array variables.
        let e = s.resolve(env(&[("SLURM_JOB_ID", "7")])).unwrap_err();
        assert!(e.contains("SLURM_ARRAY_TASK_ID"), "{e}");
        // --array=0,3,7: three tasks whose ids are not evenly spaced.
        let e = s
            .resolve(env(&[
                ("SLURM_ARRAY_TASK_ID", "3"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
                ("SLURM_ARRAY_TASK_MIN", "0"),
                ("SLURM_ARRAY_TASK_MAX", "7"),
            ]))
            .unwrap_err();
        assert!(e.contains("evenly spaced"), "{e}");
        let e = s
            .resolve(env(&[
                ("SLURM_ARRAY_TASK_ID", "x"),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ]))
            .unwrap_err();
        assert!(e.contains("not a task number"), "{e}");
    }

    #[test]
    fn shard_files_carry_the_shard() {
        let s = Shard::new(2, 4).unwrap();
        assert_eq!(
            s.file_name(std::path::Path::new("out/report.json")),
            std::path::Path::new("out/report.shard-2-of-4.json")
        );
        assert_eq!(Shard::parse_tag(&s.tag()), Some(s));
        assert_eq!(Shard::parse_tag("shard-4-of-4"), None);
    }
}
