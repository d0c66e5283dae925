//! Which column of scattered samples is x, y, z, the time and each value: by name from a
//! CSV header (any order), else by position (x, y, z first), with a sentence saying so.

/// Which column of scattered samples holds their time (`fit --time-column`).
#[derive(Clone, Debug, Default, PartialEq)]
pub enum TimeColumn {
    /// A CSV header's `t` or `time` column, or the `time_column` of a `.npy`'s sidecar
    /// (`gen --rf moving-source` writes one); else none.
    #[default]
    Auto,
    /// This column (0-based among all columns; x, y, z are 0 to 2).
    Index(usize),
    /// The column a CSV header names so.
    Name(String),
}

impl std::str::FromStr for TimeColumn {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        if s.is_empty() {
            return Err(
                "expected a column number (0-based, e.g. 3) or a CSV header's name (e.g. t)".into(),
            );
        }
        Ok(match s.parse::<usize>() {
            Ok(i) => TimeColumn::Index(i),
            Err(_) => TimeColumn::Name(s.to_string()),
        })
    }
}

/// The roles of the columns of scattered samples (0-based column numbers).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Columns {
    /// The header's names, where the file has a header.
    pub names: Option<Vec<String>>,
    /// The columns of x, y and z.
    pub xyz: [usize; 3],
    /// The time's column, if any.
    pub time: Option<usize>,
    /// The value columns in order: column `values[i]` becomes `feat_i`.
    pub values: Vec<usize>,
    /// Where the time column came from: a header's name, `--time-column`, a sidecar.
    pub time_from: Option<String>,
    /// Notes on the columns (a name close to `t` or `time` read as a value).
    #[serde(skip)]
    pub notes: Vec<String>,
}

/// A header name as matched: trimmed, quotes and a trailing unit in brackets
/// (`x (m)`, `t[s]`) dropped, lower case.
pub fn role_name(name: &str) -> String {
    let n = name.trim().trim_matches('"').trim();
    let n = match n.find(['(', '[']) {
        Some(i) if i > 0 && (n.ends_with(')') || n.ends_with(']')) => n[..i].trim(),
        _ => n,
    };
    n.to_lowercase()
}

/// True for a name that looks meant as the time but is not `t` or `time`: one letter
/// off `time` (`tme`, `tiem`, `times`) or starting with `time` or `t_`.
pub fn close_to_time(name: &str) -> bool {
    let n = role_name(name);
    if n == "t" || n == "time" {
        return false;
    }
    n.starts_with("time") || n.starts_with("t_") || edit_distance(&n, "time") <= 1
}

/// The optimal-string-alignment distance (insertions, deletions, substitutions and
/// swaps of neighbours).
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, v) in d[0].iter_mut().enumerate() {
        *v = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut v = (d[i - 1][j] + 1)
                .min(d[i][j - 1] + 1)
                .min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                v = v.min(d[i - 2][j - 2] + 1);
            }
            d[i][j] = v;
        }
    }
    d[a.len()][b.len()]
}

impl Columns {
    /// Header-less samples: x, y, z in columns 0 to 2, the time in `time` (checked by the
    /// caller), the values in the other columns.
    pub fn positional(cols: usize, time: Option<usize>, time_from: Option<String>) -> Columns {
        Columns {
            names: None,
            xyz: [0, 1, 2],
            time,
            values: (3..cols).filter(|&c| Some(c) != time).collect(),
            time_from,
            notes: Vec::new(),
        }
    }

    /// The roles a CSV header's `names` give: x, y, z (and `t` / `time`, or the
    /// `--time-column`) by name in any column, the values the rest. An error sentence
    /// where it names no x, y or z, names one twice, or leaves no value.
    pub fn from_header(names: &[String], time: &TimeColumn) -> Result<Columns, String> {
        let list = names.join(", ");
        let roles: Vec<String> = names.iter().map(|n| role_name(n)).collect();
        let find = |want: &str| -> Result<Option<usize>, String> {
            let at: Vec<usize> = (0..roles.len()).filter(|&c| roles[c] == want).collect();
            match at[..] {
                [] => Ok(None),
                [c] => Ok(Some(c)),
                _ => Err(format!(
                    "its header names {want} in columns {} ({list}); name each role once",
                    at.iter()
                        .map(usize::to_string)
                        .collect::<Vec<_>>()
                        .join(" and ")
                )),
            }
        };
        let xyz = [find("x")?, find("y")?, find("z")?];
        let missing: Vec<&str> = ["x", "y", "z"]
            .iter()
            .zip(xyz)
            .filter(|(_, c)| c.is_none())
            .map(|(n, _)| *n)
            .collect();
        if missing.len() == 3 {
            return Err(format!(
                "its header ({list}) names no x, y or z column; name the coordinate columns x, y and z (any order; a unit in brackets may follow, e.g. x (m))"
            ));
        }
        if !missing.is_empty() {
            return Err(format!(
                "its header ({list}) names no {} column; name the coordinate columns x, y and z (any order; a unit in brackets may follow, e.g. x (m))",
                missing.join(" or ")
            ));
        }
        let xyz = xyz.map(|c| c.unwrap_or_default());
        let (time, time_from) = match time {
            TimeColumn::Auto => {
                let t = find("t")?;
                let time = find("time")?;
                if let (Some(a), Some(b)) = (t, time) {
                    return Err(format!("its header names both t (column {a}) and time (column {b}); name one of them the time, or pass --time-column"));
                }
                let c = t.or(time);
                (
                    c,
                    c.map(|c| format!("the header's \"{}\"", names[c].trim())),
                )
            }
            TimeColumn::Index(c) => {
                if *c >= names.len() {
                    return Err(format!(
                        "--time-column {c}: the samples have {} columns (0 to {}: {list})",
                        names.len(),
                        names.len() - 1
                    ));
                }
                (Some(*c), Some(format!("--time-column {c}")))
            }
            TimeColumn::Name(name) => {
                let c = names
                    .iter()
                    .position(|n| n.trim().trim_matches('"') == name)
                    .or_else(|| roles.iter().position(|r| *r == role_name(name)))
                    .ok_or_else(|| {
                        format!(
                            "--time-column {name}: its header names no such column (it has {list})"
                        )
                    })?;
                (Some(c), Some(format!("--time-column {name}")))
            }
        };
        if let Some(c) = time {
            if let Some(a) = xyz.iter().position(|&x| x == c) {
                return Err(format!(
                    "--time-column {c} is {} (the header's \"{}\"); the time is another column",
                    ["x", "y", "z"][a],
                    names[c].trim()
                ));
            }
        }
        let values: Vec<usize> = (0..names.len())
            .filter(|c| !xyz.contains(c) && Some(*c) != time)
            .collect();
        if values.is_empty() {
            return Err(format!(
                "its header ({list}) leaves no value column besides x, y, z{}; samples need at least one value",
                if time.is_some() { " and the time" } else { "" }
            ));
        }
        let notes = values
            .iter()
            .enumerate()
            .filter(|(_, &c)| close_to_time(&names[c]))
            .map(|(i, &c)| {
                let n = names[c].trim();
                format!(
                    "column {c} \"{n}\" is read as a value (feat_{i}), not as the time; if it is the time, name it t or time, or pass --time-column {c}"
                )
            })
            .collect();
        Ok(Columns {
            names: Some(names.to_vec()),
            xyz,
            time,
            values,
            time_from,
            notes,
        })
    }

    /// One sentence: which column plays which role (0-based column numbers, with the
    /// header's names).
    pub fn describe(&self) -> String {
        let col = |c: usize| match &self.names {
            Some(n) => format!("column {c} \"{}\"", n[c].trim()),
            None => format!("column {c}"),
        };
        let mut parts: Vec<String> = ["x", "y", "z"]
            .iter()
            .zip(self.xyz)
            .map(|(a, c)| format!("{a} = {}", col(c)))
            .collect();
        parts.push(match (self.time, &self.time_from) {
            (Some(c), Some(from)) => format!("time = {} ({from})", col(c)),
            (Some(c), None) => format!("time = {}", col(c)),
            (None, _) => "no time".into(),
        });
        if self.values.len() <= 8 {
            parts.extend(
                self.values
                    .iter()
                    .enumerate()
                    .map(|(i, &c)| format!("feat_{i} = {}", col(c))),
            );
        } else {
            parts.push(format!(
                "feat_0..feat_{} = the other {} columns in order",
                self.values.len() - 1,
                self.values.len()
            ));
        }
        format!(
            "{} (columns counted from 0{})",
            parts.join(", "),
            if self.names.is_some() {
                ", roles from the header"
            } else {
                "; no header: x, y, z first"
            }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(s: &str) -> Vec<String> {
        s.split(',').map(String::from).collect()
    }

    #[test]
    fn header_roles_by_name_in_any_order() {
        let c = Columns::from_header(&names("power,x,y,z"), &TimeColumn::Auto).unwrap();
        assert_eq!(
            (c.xyz, c.time, c.values.clone()),
            ([1, 2, 3], None, vec![0])
        );
        assert!(
            c.describe().contains("feat_0 = column 0 \"power\""),
            "{}",
            c.describe()
        );
        let c = Columns::from_header(&names("Time (s),Z,y [m],x,a,b"), &TimeColumn::Auto).unwrap();
        assert_eq!((c.xyz, c.time, c.values), ([3, 2, 1], Some(0), vec![4, 5]));
        let e = Columns::from_header(&names("x,y,zz,power"), &TimeColumn::Auto).unwrap_err();
        assert!(
            e.contains("names no z column") && e.contains("x, y, zz, power"),
            "{e}"
        );
        let e = Columns::from_header(&names("a,b,c,d"), &TimeColumn::Auto).unwrap_err();
        assert!(
            e.contains("names no x, y or z column") && e.contains("a, b, c, d"),
            "{e}"
        );
        let e = Columns::from_header(&names("x,y,z,x,v"), &TimeColumn::Auto).unwrap_err();
        assert!(e.contains("names x in columns 0 and 3"), "{e}");
    }

    #[test]
    fn a_name_close_to_time_gets_a_note() {
        let c = Columns::from_header(&names("x,y,z,tme,power"), &TimeColumn::Auto).unwrap();
        assert_eq!(c.time, None);
        assert_eq!(c.notes.len(), 1);
        assert!(
            c.notes[0].contains("\"tme\" is read as a value (feat_0)"),
            "{:?}",
            c.notes
        );
        for n in ["tme", "tiem", "times", "Timestamp", "t_s", "tim"] {
            assert!(close_to_time(n), "{n}");
        }
        for n in ["t", "time", "T (s)", "power", "x", "temp", "v"] {
            assert!(!close_to_time(n), "{n}");
        }
    }
}
