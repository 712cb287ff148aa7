//! A tiny command-line parser (no dependency): positional arguments, `--flag`,
//! `--key value`, `-o value`, and `--help`/`-h`. Each subcommand declares which
//! options take a value and which are switches, so typos are errors.

use point2quad::Error;

/// Parsed arguments of one subcommand.
#[derive(Debug, Default)]
pub struct Args {
    pub positional: Vec<String>,
    values: Vec<(String, String)>,
    switches: Vec<String>,
    pub help: bool,
}

/// What a subcommand accepts: option names (with leading dashes) that take a value,
/// and those that are plain switches.
pub struct Spec<'a> {
    pub valued: &'a [&'a str],
    pub switches: &'a [&'a str],
}

impl Args {
    /// Parses `argv` (without the program and subcommand names) against `spec`.
    pub fn parse(cmd: &str, argv: &[String], spec: &Spec) -> Result<Args, Error> {
        let mut a = Args::default();
        let mut i = 0;
        while i < argv.len() {
            let s = &argv[i];
            if s == "-h" || s == "--help" {
                a.help = true;
            } else if s == "--" {
                a.positional.extend(argv[i + 1..].iter().cloned());
                break;
            } else if s.starts_with('-') && s.len() > 1 {
                let (name, inline) = match s.split_once('=') {
                    Some((n, v)) => (n.to_string(), Some(v.to_string())),
                    None => (s.clone(), None),
                };
                if spec.valued.contains(&name.as_str()) {
                    let v = match inline {
                        Some(v) => v,
                        None => {
                            i += 1;
                            argv.get(i).cloned().ok_or_else(|| {
                                Error::Usage(format!(
                                    "{cmd}: option {name} needs a value (see `point2quad {cmd} --help`)"
                                ))
                            })?
                        }
                    };
                    if v.is_empty() {
                        // `-o=` or `-o ""`: an empty file name would only fail later,
                        // with an error that cannot name the file.
                        return Err(Error::Usage(format!(
                            "{cmd}: option {name} needs a non-empty value (see `point2quad {cmd} --help`)"
                        )));
                    }
                    // Given twice (`-o a -o b`, or `-o a --output b`): which one was
                    // meant cannot be known, and taking either silently surprises.
                    fn alias(n: &str) -> &str {
                        if n == "--output" {
                            "-o"
                        } else {
                            n
                        }
                    }
                    if let Some((prev, _)) = a.values.iter().find(|(n, _)| alias(n) == alias(&name)) {
                        return Err(Error::Usage(format!(
                            "{cmd}: option {name} given twice ({prev} already set; see `point2quad {cmd} --help`)"
                        )));
                    }
                    a.values.push((name, v));
                } else if spec.switches.contains(&name.as_str()) && inline.is_none() {
                    // Harmless, but a repeated switch is most often a pasted command
                    // line gone wrong; refused like a repeated option.
                    if a.switches.contains(&name) {
                        return Err(Error::Usage(format!(
                            "{cmd}: option {name} given twice (see `point2quad {cmd} --help`)"
                        )));
                    }
                    a.switches.push(name);
                } else {
                    return Err(Error::Usage(format!(
                        "{cmd}: unknown option {s} (see `point2quad {cmd} --help`)"
                    )));
                }
            } else {
                a.positional.push(s.clone());
            }
            i += 1;
        }
        Ok(a)
    }

    /// The last value given for option `name`.
    pub fn value(&self, name: &str) -> Option<&str> {
        self.values.iter().rev().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }

    /// The value of `name` parsed as `T`, or `default` when absent.
    pub fn parsed<T: std::str::FromStr>(&self, cmd: &str, name: &str, default: T) -> Result<T, Error> {
        match self.value(name) {
            None => Ok(default),
            Some(v) => v.parse().map_err(|_| {
                Error::Usage(format!("{cmd}: {name}: cannot parse {v:?} (see `point2quad {cmd} --help`)"))
            }),
        }
    }

    /// [`Args::parsed`], then checked to lie in `lo..=hi`; otherwise a usage error
    /// naming the option, the bounds, the value and `why` (the reason for the bound).
    pub fn parsed_in<T>(&self, cmd: &str, name: &str, default: T, lo: T, hi: T, why: &str) -> Result<T, Error>
    where
        T: std::str::FromStr + PartialOrd + std::fmt::Display,
    {
        let v = self.parsed(cmd, name, default)?;
        // Written so that NaN (which compares false with everything) is refused too.
        if !(v >= lo && v <= hi) {
            // As typed: `1e300` read as f64 printed 301 digits (session 24's audit).
            let got = self.value(name).map_or_else(|| v.to_string(), str::to_string);
            return Err(Error::Usage(format!(
                "{cmd}: {name} must be between {lo} and {hi}, got {got} ({why})"
            )));
        }
        Ok(v)
    }

    /// Whether switch `name` was given.
    pub fn switch(&self, name: &str) -> bool {
        self.switches.iter().any(|s| s == name)
    }

    /// Exactly `n` positional arguments, else a usage error naming `what`.
    pub fn expect_positional(&self, cmd: &str, n: usize, what: &str) -> Result<&[String], Error> {
        if self.positional.len() != n {
            return Err(Error::Usage(format!(
                "{cmd}: expected {what}, got {} argument(s) (see `point2quad {cmd} --help`)",
                self.positional.len()
            )));
        }
        Ok(&self.positional)
    }

    /// A required option's value.
    pub fn required(&self, cmd: &str, name: &str) -> Result<&str, Error> {
        self.value(name)
            .ok_or_else(|| Error::Usage(format!("{cmd}: missing {name} (see `point2quad {cmd} --help`)")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    fn v(s: &[&str]) -> Vec<String> {
        s.iter().map(|x| x.to_string()).collect()
    }
    #[test]
    fn parses_values_switches_and_rejects_unknown() {
        let spec = Spec { valued: &["-o", "--seed"], switches: &["--json"] };
        let a = Args::parse("x", &v(&["in.xyz", "-o", "out.obj", "--seed=3", "--json"]), &spec).unwrap();
        assert_eq!(a.positional, vec!["in.xyz"]);
        assert_eq!(a.value("-o"), Some("out.obj"));
        assert_eq!(a.parsed("x", "--seed", 0u64).unwrap(), 3);
        assert!(a.switch("--json"));
        assert!(Args::parse("x", &v(&["--bogus"]), &spec).is_err());
        assert!(Args::parse("x", &v(&["-o"]), &spec).is_err());
        assert!(Args::parse("x", &v(&["--seed=abc"]), &spec).unwrap().parsed("x", "--seed", 0u64).is_err());
    }

    /// Regression: `-o=` gave an empty output name, and the write failed with
    /// ": not a file path", naming nothing.
    #[test]
    fn bounded_values() {
        let spec = Spec { valued: &["--k"], switches: &[] };
        let k = |argv: &[&str]| {
            Args::parse("x", &v(argv), &spec).unwrap().parsed_in("x", "--k", 20usize, 3, 64, "why")
        };
        assert_eq!(k(&[]).unwrap(), 20);
        assert_eq!(k(&["--k", "3"]).unwrap(), 3);
        assert_eq!(k(&["--k", "64"]).unwrap(), 64);
        for bad in ["2", "65", "18446744073709551615"] {
            let e = k(&["--k", bad]).unwrap_err().to_string();
            assert!(
                e.contains("--k must be between 3 and 64") && e.contains(bad) && e.contains("why"),
                "{e}"
            );
        }
        assert!(k(&["--k", "-1"]).unwrap_err().to_string().contains("cannot parse"));
        // A float out of range is echoed as typed, not with all its digits.
        let spec = Spec { valued: &["--f"], switches: &[] };
        let e = Args::parse("x", &v(&["--f", "1e300"]), &spec)
            .unwrap()
            .parsed_in("x", "--f", 0.5f64, 0.0, 1.0, "why")
            .unwrap_err()
            .to_string();
        assert!(e.contains("got 1e300 (why)") && e.len() < 100, "{e}");
    }

    #[test]
    fn empty_option_values_are_usage_errors() {
        let spec = Spec { valued: &["-o"], switches: &[] };
        for argv in [&["-o="][..], &["-o", ""][..]] {
            let e = Args::parse("x", &v(argv), &spec).unwrap_err().to_string();
            assert!(e.contains("-o needs a non-empty value"), "{e}");
        }
    }
}
