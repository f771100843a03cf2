//! The `[[interface]]` tables of a study file: which regions slide on each other and how
//! ([`parse_interfaces`]). The model split along them is built by `crate::interfaces`.

/// How the two regions of an interface hold together.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InterfaceLaw {
    /// Shared nodes (the mesh as meshed).
    Tied,
    /// Normal contact only.
    Frictionless,
    /// Coulomb friction with coefficient `mu`.
    Friction { mu: f64 },
}

/// One `[[interface]]` table.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceSpec {
    /// The two regions (element sets), slave first.
    pub between: [String; 2],
    pub law: InterfaceLaw,
}

impl InterfaceSpec {
    /// The interface's name in the model: `A_B`.
    pub fn name(&self) -> String {
        format!(
            "{}_{}",
            self.between[0].to_ascii_uppercase(),
            self.between[1].to_ascii_uppercase()
        )
    }
}

/// The `[[interface]]` tables of a parsed study file (`doc`, its top-level table); none when
/// the key is absent. Errors name the table's position and key.
pub fn parse_interfaces(doc: &toml::Value) -> Result<Vec<InterfaceSpec>, String> {
    let Some(list) = doc.get("interface") else {
        return Ok(Vec::new());
    };
    let Some(list) = list.as_array() else {
        return Err("interface: must be an array of tables ([[interface]])".into());
    };
    let mut specs = Vec::with_capacity(list.len());
    for (i, table) in list.iter().enumerate() {
        let at = format!("[[interface]] number {}", i + 1);
        let Some(table) = table.as_table() else {
            return Err(format!("{at}: must be a table"));
        };
        for key in table.keys() {
            if !matches!(key.as_str(), "between" | "kind" | "mu") {
                return Err(format!("{at}: unknown key {key} (between, kind, mu)"));
            }
        }
        let between = match table.get("between").and_then(|v| v.as_array()) {
            Some(v) if v.len() == 2 && v.iter().all(|s| s.is_str()) => [
                v[0].as_str().unwrap_or_default().to_string(),
                v[1].as_str().unwrap_or_default().to_string(),
            ],
            _ => return Err(format!("{at}: between must be two region names, e.g. between = [\"QUADRICEPS\", \"ISCHIO\"]")),
        };
        if between[0].eq_ignore_ascii_case(&between[1]) {
            return Err(format!("{at}: between names {} twice", between[0]));
        }
        let kind = match table.get("kind") {
            None => {
                return Err(format!(
                    "{at}: kind is missing (tied, frictionless or friction)"
                ))
            }
            Some(v) => v.as_str().unwrap_or_default(),
        };
        let mu = match table.get("mu") {
            None => None,
            Some(v) => match v.as_float().or_else(|| v.as_integer().map(|k| k as f64)) {
                Some(mu) if mu.is_finite() && mu >= 0.0 => Some(mu),
                _ => return Err(format!("{at}: mu must be a number ≥ 0, got {v}")),
            },
        };
        let law = match (kind, mu) {
            ("tied", None) => InterfaceLaw::Tied,
            ("frictionless", None) => InterfaceLaw::Frictionless,
            ("friction", Some(mu)) => InterfaceLaw::Friction { mu },
            ("friction", None) => return Err(format!("{at}: kind = \"friction\" needs mu")),
            ("tied" | "frictionless", Some(_)) => {
                return Err(format!(
                    "{at}: mu is only for kind = \"friction\", not {kind}"
                ))
            }
            _ => {
                return Err(format!(
                    "{at}: kind must be one of tied, frictionless, friction; got {kind:?}"
                ))
            }
        };
        specs.push(InterfaceSpec { between, law });
    }
    Ok(specs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(text: &str) -> toml::Value {
        text.parse().unwrap()
    }

    fn err(text: &str) -> String {
        parse_interfaces(&doc(text)).unwrap_err().to_string()
    }

    #[test]
    fn parses_the_three_kinds_and_rejects_bad_tables() {
        let specs = parse_interfaces(&doc(
            "[[interface]]\nbetween = [\"QUADRICEPS\", \"ISCHIO\"]\nkind = \"frictionless\"\n\
             [[interface]]\nbetween = [\"FAT\", \"QUADRICEPS\"]\nkind = \"friction\"\nmu = 0.2\n\
             [[interface]]\nbetween = [\"FAT\", \"ISCHIO\"]\nkind = \"tied\"\n",
        ))
        .unwrap();
        assert_eq!(specs.len(), 3);
        assert_eq!(specs[0].law, InterfaceLaw::Frictionless);
        assert_eq!(specs[0].name(), "QUADRICEPS_ISCHIO");
        assert_eq!(specs[1].law, InterfaceLaw::Friction { mu: 0.2 });
        assert_eq!(specs[2].law, InterfaceLaw::Tied);
        assert!(parse_interfaces(&doc("x = 1")).unwrap().is_empty());
        let e = err("[[interface]]\nbetween = [\"A\", \"B\"]\nkind = \"friction\"\nmu = -0.1");
        assert!(
            e.contains("[[interface]] number 1") && e.contains("mu"),
            "{e}"
        );
        let e = err("[[interface]]\nbetween = [\"A\", \"B\"]\nkind = \"tied\"\nmu = 0.1");
        assert!(e.contains("mu is only for"), "{e}");
        let e = err("[[interface]]\nbetween = [\"A\", \"B\"]\nkind = \"friction\"");
        assert!(e.contains("needs mu"), "{e}");
        let e = err("[[interface]]\nbetween = [\"A\", \"B\"]\nkind = \"glued\"");
        assert!(e.contains("kind must be"), "{e}");
        let e = err("[[interface]]\nbetween = [\"A\"]\nkind = \"tied\"");
        assert!(e.contains("between must be"), "{e}");
        let e = err("[[interface]]\nbetween = [\"A\", \"a\"]\nkind = \"tied\"");
        assert!(e.contains("twice"), "{e}");
        let e = err("[[interface]]\nbetween = [\"A\", \"B\"]\nkind = \"tied\"\npenalty = 3");
        assert!(e.contains("unknown key penalty"), "{e}");
    }
}
