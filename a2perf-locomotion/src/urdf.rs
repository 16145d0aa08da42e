//! A small URDF reader: links (mass, inertial origin) and joints (type, parent, child, origin,
//! axis, limits). It reads the subset of XML that URDF files use (elements, attributes, comments,
//! the `<?xml?>` declaration); meshes, materials and Gazebo extensions are skipped.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Errors reading a URDF file.
#[derive(Debug, thiserror::Error)]
pub enum UrdfError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The XML or the URDF content is malformed.
    #[error("{origin}:{line}: {reason}")]
    Syntax {
        /// File name.
        origin: String,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

/// An XML element.
#[derive(Clone, Debug, Default, PartialEq)]
struct Element {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Element>,
    line: usize,
}

impl Element {
    fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
    fn child(&self, name: &str) -> Option<&Element> {
        self.children.iter().find(|c| c.name == name)
    }
}

struct XmlReader<'a> {
    text: &'a str,
    pos: usize,
    origin: &'a str,
}

impl<'a> XmlReader<'a> {
    fn line(&self) -> usize {
        self.text[..self.pos.min(self.text.len())]
            .bytes()
            .filter(|b| *b == b'\n')
            .count()
            + 1
    }
    fn err(&self, reason: impl Into<String>) -> UrdfError {
        UrdfError::Syntax {
            origin: self.origin.into(),
            line: self.line(),
            reason: reason.into(),
        }
    }
    fn rest(&self) -> &'a str {
        &self.text[self.pos..]
    }
    fn skip_ws(&mut self) {
        let r = self.rest();
        self.pos += r.len() - r.trim_start().len();
    }
    /// Skips text, comments, declarations; stops at the next element tag (`<name` or `</`).
    fn skip_misc(&mut self) -> Result<(), UrdfError> {
        loop {
            let r = self.rest();
            let Some(i) = r.find('<') else {
                self.pos = self.text.len();
                return Ok(());
            };
            self.pos += i;
            let r = self.rest();
            if r.starts_with("<!--") {
                let end = r
                    .find("-->")
                    .ok_or_else(|| self.err("unterminated comment"))?;
                self.pos += end + 3;
            } else if r.starts_with("<?") {
                let end = r
                    .find("?>")
                    .ok_or_else(|| self.err("unterminated declaration"))?;
                self.pos += end + 2;
            } else if r.starts_with("<!") {
                let end = r
                    .find('>')
                    .ok_or_else(|| self.err("unterminated declaration"))?;
                self.pos += end + 1;
            } else {
                return Ok(());
            }
        }
    }
    fn name(&mut self) -> Result<String, UrdfError> {
        let r = self.rest();
        let n = r
            .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':' || c == '-' || c == '.'))
            .unwrap_or(r.len());
        if n == 0 {
            return Err(self.err("expected a name"));
        }
        self.pos += n;
        Ok(r[..n].to_string())
    }
    fn element(&mut self, depth: usize) -> Result<Element, UrdfError> {
        if depth > 64 {
            return Err(self.err("elements nested too deeply"));
        }
        let line = self.line();
        if !self.rest().starts_with('<') {
            return Err(self.err("expected `<`"));
        }
        self.pos += 1;
        let name = self.name()?;
        let mut el = Element {
            name,
            line,
            ..Element::default()
        };
        loop {
            self.skip_ws();
            let r = self.rest();
            if r.starts_with("/>") {
                self.pos += 2;
                return Ok(el);
            }
            if r.starts_with('>') {
                self.pos += 1;
                break;
            }
            if r.is_empty() {
                return Err(self.err(format!("unterminated tag <{}>", el.name)));
            }
            let key = self.name()?;
            self.skip_ws();
            if !self.rest().starts_with('=') {
                return Err(self.err(format!("attribute `{key}` has no value")));
            }
            self.pos += 1;
            self.skip_ws();
            let q = self
                .rest()
                .chars()
                .next()
                .filter(|c| *c == '"' || *c == '\'')
                .ok_or_else(|| self.err(format!("attribute `{key}` value is not quoted")))?;
            self.pos += 1;
            let end = self
                .rest()
                .find(q)
                .ok_or_else(|| self.err(format!("unterminated value of `{key}`")))?;
            let value = self.rest()[..end].to_string();
            self.pos += end + 1;
            el.attrs.push((key, value));
        }
        loop {
            self.skip_misc()?;
            let r = self.rest();
            if r.is_empty() {
                return Err(self.err(format!("element <{}> is not closed", el.name)));
            }
            if let Some(stripped) = r.strip_prefix("</") {
                let n = stripped
                    .find('>')
                    .ok_or_else(|| self.err("unterminated end tag"))?;
                let closing = stripped[..n].trim();
                if closing != el.name {
                    return Err(self.err(format!(
                        "end tag </{closing}> does not match <{}> opened on line {}",
                        el.name, el.line
                    )));
                }
                self.pos += 2 + n + 1;
                return Ok(el);
            }
            el.children.push(self.element(depth + 1)?);
        }
    }
}

fn parse_xml(text: &str, origin: &str) -> Result<Element, UrdfError> {
    let mut r = XmlReader {
        text,
        pos: 0,
        origin,
    };
    r.skip_misc()?;
    let root = r.element(0)?;
    r.skip_misc()?;
    if !r.rest().trim().is_empty() {
        return Err(r.err("content after the root element"));
    }
    Ok(root)
}

/// A URDF link's inertial data.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfLink {
    /// Link name.
    pub name: String,
    /// Mass \[kg\] (0 when the link has no `<inertial>`).
    pub mass: f64,
    /// Inertial origin (COM) in the link frame.
    pub com: Vector3<f64>,
}

/// A URDF joint.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfJoint {
    /// Joint name.
    pub name: String,
    /// `revolute`, `fixed`, `continuous`, `prismatic`, …
    pub kind: String,
    /// Parent link name.
    pub parent: String,
    /// Child link name.
    pub child: String,
    /// Joint frame in the parent link frame.
    pub origin: Isometry3<f64>,
    /// Joint axis in the joint frame.
    pub axis: Vector3<f64>,
    /// Position limits, if given.
    pub limits: Option<(f64, f64)>,
}

/// A parsed URDF robot (kinematic tree and masses).
///
/// ```
/// let text = r#"<robot name="r"><link name="a"><inertial><mass value="2"/></inertial></link></robot>"#;
/// let robot = a2perf_locomotion::UrdfRobot::parse(text, "r.urdf").unwrap();
/// assert_eq!(robot.link("a").unwrap().mass, 2.0);
/// assert!(a2perf_locomotion::UrdfRobot::parse("<robot><link>", "bad.urdf").is_err());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfRobot {
    /// Robot name.
    pub name: String,
    /// Links in file order.
    pub links: Vec<UrdfLink>,
    /// Joints in file order.
    pub joints: Vec<UrdfJoint>,
}

fn floats<const N: usize>(
    s: &str,
    origin: &str,
    line: usize,
    what: &str,
) -> Result<[f64; N], UrdfError> {
    let bad = || UrdfError::Syntax {
        origin: origin.into(),
        line,
        reason: format!("`{what}` needs {N} numbers, found `{s}`"),
    };
    let mut out = [0.0; N];
    let mut it = s.split_whitespace();
    for o in &mut out {
        *o = it
            .next()
            .and_then(|t| t.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .ok_or_else(bad)?;
    }
    if it.next().is_some() {
        return Err(bad());
    }
    Ok(out)
}

fn origin_of(el: Option<&Element>, origin: &str) -> Result<Isometry3<f64>, UrdfError> {
    let Some(el) = el else {
        return Ok(Isometry3::identity());
    };
    let xyz = match el.attr("xyz") {
        Some(s) => floats::<3>(s, origin, el.line, "xyz")?,
        None => [0.0; 3],
    };
    let rpy = match el.attr("rpy") {
        Some(s) => floats::<3>(s, origin, el.line, "rpy")?,
        None => [0.0; 3],
    };
    Ok(Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    ))
}

impl UrdfRobot {
    /// Reads a URDF file.
    pub fn load(path: &Path) -> Result<Self, UrdfError> {
        let text = std::fs::read_to_string(path).map_err(|source| UrdfError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses URDF text; `origin` names the source in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, UrdfError> {
        let root = parse_xml(text, origin)?;
        let err = |line: usize, reason: String| UrdfError::Syntax {
            origin: origin.into(),
            line,
            reason,
        };
        if root.name != "robot" {
            return Err(err(
                root.line,
                format!("root element is <{}>, not <robot>", root.name),
            ));
        }
        let mut links = Vec::new();
        let mut joints = Vec::new();
        for el in &root.children {
            match el.name.as_str() {
                "link" => {
                    let name = el
                        .attr("name")
                        .ok_or_else(|| err(el.line, "link without a name".into()))?;
                    let (mut mass, mut com) = (0.0, Vector3::zeros());
                    if let Some(inertial) = el.child("inertial") {
                        if let Some(m) = inertial.child("mass") {
                            let v = m
                                .attr("value")
                                .ok_or_else(|| err(m.line, "mass without a value".into()))?;
                            mass = floats::<1>(v, origin, m.line, "mass")?[0];
                            if mass < 0.0 {
                                return Err(err(m.line, format!("negative mass {mass}")));
                            }
                        }
                        com = origin_of(inertial.child("origin"), origin)?
                            .translation
                            .vector;
                    }
                    links.push(UrdfLink {
                        name: name.into(),
                        mass,
                        com,
                    });
                }
                "joint" => {
                    let get = |k: &str| {
                        el.attr(k)
                            .map(str::to_string)
                            .ok_or_else(|| err(el.line, format!("joint without `{k}`")))
                    };
                    let name = get("name")?;
                    let kind = get("type")?;
                    let link_of = |tag: &str| {
                        el.child(tag)
                            .and_then(|c| c.attr("link"))
                            .map(str::to_string)
                            .ok_or_else(|| {
                                err(el.line, format!("joint `{name}` has no <{tag} link>"))
                            })
                    };
                    let parent = link_of("parent")?;
                    let child = link_of("child")?;
                    let axis = match el.child("axis").and_then(|a| a.attr("xyz").map(|s| (a, s))) {
                        Some((a, s)) => {
                            let v = floats::<3>(s, origin, a.line, "axis")?;
                            Vector3::new(v[0], v[1], v[2])
                        }
                        None => Vector3::x(),
                    };
                    let limits = match el.child("limit") {
                        Some(l) if kind != "fixed" && kind != "continuous" => {
                            let lo = l.attr("lower").unwrap_or("0");
                            let hi = l.attr("upper").unwrap_or("0");
                            let lo = floats::<1>(lo, origin, l.line, "lower")?[0];
                            let hi = floats::<1>(hi, origin, l.line, "upper")?[0];
                            Some((lo, hi))
                        }
                        _ => None,
                    };
                    joints.push(UrdfJoint {
                        origin: origin_of(el.child("origin"), origin)?,
                        name,
                        kind,
                        parent,
                        child,
                        axis,
                        limits,
                    });
                }
                _ => {}
            }
        }
        for j in &joints {
            for l in [&j.parent, &j.child] {
                if !links.iter().any(|k: &UrdfLink| &k.name == l) {
                    return Err(err(
                        root.line,
                        format!("joint `{}` refers to unknown link `{l}`", j.name),
                    ));
                }
            }
        }
        Ok(Self {
            name: root.attr("name").unwrap_or("").to_string(),
            links,
            joints,
        })
    }

    /// The link called `name`.
    pub fn link(&self, name: &str) -> Option<&UrdfLink> {
        self.links.iter().find(|l| l.name == name)
    }

    /// The joint called `name`.
    pub fn joint(&self, name: &str) -> Option<&UrdfJoint> {
        self.joints.iter().find(|j| j.name == name)
    }

    /// Total mass of all links.
    pub fn total_mass(&self) -> f64 {
        self.links.iter().map(|l| l.mass).sum()
    }

    /// Pose of link `name` in the root link's frame with the given joint angles (missing angles
    /// are 0). `None` if the link is unknown or the tree has a cycle.
    pub fn link_pose(&self, name: &str, angles: &BTreeMap<String, f64>) -> Option<Isometry3<f64>> {
        let mut pose = Isometry3::identity();
        let mut current = name;
        for _ in 0..=self.joints.len() {
            let Some(j) = self.joints.iter().find(|j| j.child == current) else {
                return self.link(current).map(|_| pose);
            };
            let q = angles.get(&j.name).copied().unwrap_or(0.0);
            let motion = match j.kind.as_str() {
                "revolute" | "continuous" => Isometry3::from_parts(
                    Translation3::identity(),
                    UnitQuaternion::from_scaled_axis(j.axis.normalize() * q),
                ),
                "prismatic" => Isometry3::from_parts(
                    Translation3::from(j.axis.normalize() * q),
                    UnitQuaternion::identity(),
                ),
                _ => Isometry3::identity(),
            };
            pose = j.origin * motion * pose;
            current = &j.parent;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_documents_are_errors_with_lines() {
        let cases = [
            "",
            "<robot>",
            "<robot><link name=\"a\"></robot>",
            "<robot name=x></robot>",
            "<robot><link name=\"a\"><inertial><mass value=\"abc\"/></inertial></link></robot>",
            "<robot><joint name=\"j\" type=\"fixed\"><parent link=\"a\"/><child link=\"b\"/></joint></robot>",
            "<notrobot/>",
            "<robot><!-- unterminated </robot>",
        ];
        for c in cases {
            let e = UrdfRobot::parse(c, "t.urdf");
            assert!(e.is_err(), "accepted: {c}");
            assert!(e.unwrap_err().to_string().starts_with("t.urdf:"));
        }
    }

    #[test]
    fn chain_pose_composes_origins_and_rotations() {
        let text = r#"<?xml version="1.0"?>
<robot name="r">
  <link name="a"/>
  <link name="b"><inertial><origin xyz="0 0 0.5"/><mass value="1.5"/></inertial></link>
  <joint name="j" type="revolute">
    <parent link="a"/><child link="b"/>
    <origin xyz="1 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="2"/>
  </joint>
</robot>"#;
        let r = UrdfRobot::parse(text, "r.urdf").unwrap();
        assert_eq!(r.joint("j").unwrap().limits, Some((-1.0, 2.0)));
        assert_eq!(r.link("b").unwrap().com.z, 0.5);
        let mut q = BTreeMap::new();
        q.insert("j".to_string(), std::f64::consts::FRAC_PI_2);
        let p = r.link_pose("b", &q).unwrap() * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((p - nalgebra::Point3::new(1.0, 1.0, 0.0)).norm() < 1e-12);
    }
}
