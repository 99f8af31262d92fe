//! A skeleton's anatomy, resolved once: which joint is the pelvis, the spine (a chain from the
//! pelvis up to the thorax), the neck (a chain), the head, and on each side the clavicle, upper
//! arm, forearm, hand, thigh, shank, foot and toes. Every feature takes its parts from here:
//! retargeting, `angles`/`compare`, VMC's bone names, root motion's feet, calibration's legs,
//! subject scaling, the viewer, and the Blender add-on (`names.py`, checked against this in
//! `tests/outputs/addon_anatomy.rs`).
//!
//! # Resolution, in order
//! 1. **Declared**: a rig file's `segments:` (`pelvis`, `thorax`, `neck`, `head`,
//!    `left_clavicle`, `left_upper_arm`, `left_forearm`, `left_hand`, `left_thigh`, `left_shank`,
//!    `left_foot`, `left_toe`, and the right ones).
//! 2. **Named**: what each joint's name says ([`super::names`]: Mixamo, Unity, `UpperLeg_L`,
//!    CMU, Poser/DAZ, Axis, SlimeVR, MVN, mocopi, Rokoko, Rigify's metarig …). A limb's parts are
//!    taken down the limb: the forearm below the upper arm, the hand below the forearm, and so
//!    on; the first by depth, then by order, wins. A part missing between two found ones is the
//!    one joint between them.
//! 3. **Shape**, where the names say nothing of a limb (rest positions needed): the legs end in
//!    the lowest leaves of the skeleton, one on each side (+X is the body's left), the arms in the
//!    leaves furthest out to each side; along such a chain the upper arm (thigh) starts the two
//!    longest consecutive bones — in an arm that branches into fingers, the hand is where it last
//!    branches and the forearm and upper arm the two joints with a bone above it —, the clavicle
//!    is the joint before it, and the forearm, hand (shank, foot, toes) follow. The head is the end of the chain that rises from the thorax
//!    between the arms.
//!
//! The centre comes from the limbs: the pelvis is the lowest common ancestor of the two thighs
//! (else a joint named so, else the root), the thorax that of the two clavicles (else upper
//! arms), the spine every joint from the pelvis (exclusive) to the thorax, the neck every joint
//! from the thorax to the head (both exclusive). So a spine is a chain of any length — mocopi's
//! seven `torso_*`, MVN's four vertebrae, Poser's `abdomen`, `chest` — and two chains of
//! different lengths are paired by their place along them ([`pairs`]).

use super::Rig;
use super::names::{Word, classify};
use nalgebra::Vector3;
use std::collections::BTreeMap;

pub use super::names::Side;

/// A limb's segments, from the body out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Limb {
    Clavicle,
    UpperArm,
    Forearm,
    Hand,
    Thigh,
    Shank,
    Foot,
    Toes,
}

impl Limb {
    pub const ALL: [Limb; 8] = [
        Limb::Clavicle,
        Limb::UpperArm,
        Limb::Forearm,
        Limb::Hand,
        Limb::Thigh,
        Limb::Shank,
        Limb::Foot,
        Limb::Toes,
    ];

    /// The key a rig file's `segments:` declares it by (after `left_`/`right_`).
    pub fn key(self) -> &'static str {
        match self {
            Limb::Clavicle => "clavicle",
            Limb::UpperArm => "upper_arm",
            Limb::Forearm => "forearm",
            Limb::Hand => "hand",
            Limb::Thigh => "thigh",
            Limb::Shank => "shank",
            Limb::Foot => "foot",
            Limb::Toes => "toe",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Limb::Clavicle => "clavicle",
            Limb::UpperArm => "upper arm",
            Limb::Forearm => "forearm",
            Limb::Hand => "hand",
            Limb::Thigh => "thigh",
            Limb::Shank => "shank",
            Limb::Foot => "foot",
            Limb::Toes => "toes",
        }
    }

    fn index(self) -> usize {
        self as usize
    }

    /// Mixamo's name (after `Left`/`Right`) and Unity's.
    fn names(self) -> (&'static str, &'static str) {
        match self {
            Limb::Clavicle => ("Shoulder", "Shoulder"),
            Limb::UpperArm => ("Arm", "UpperArm"),
            Limb::Forearm => ("ForeArm", "LowerArm"),
            Limb::Hand => ("Hand", "Hand"),
            Limb::Thigh => ("UpLeg", "UpperLeg"),
            Limb::Shank => ("Leg", "LowerLeg"),
            Limb::Foot => ("Foot", "Foot"),
            Limb::Toes => ("ToeBase", "Toes"),
        }
    }
}

/// A body part: one joint, or a chain of them (the spine and the neck).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Part {
    Pelvis,
    Spine,
    Neck,
    Head,
    Limb(Side, Limb),
}

impl Part {
    /// Every part, from the pelvis up, then the left limbs, then the right.
    pub fn all() -> Vec<Part> {
        let mut out = vec![Part::Pelvis, Part::Spine, Part::Neck, Part::Head];
        for side in Side::BOTH {
            out.extend(Limb::ALL.map(|l| Part::Limb(side, l)));
        }
        out
    }

    /// The key a rig file's `segments:` declares it by (`pelvis`, `left_upper_arm`; the spine's
    /// top is `thorax`).
    pub fn key(self) -> String {
        match self {
            Part::Pelvis => "pelvis".into(),
            Part::Spine => "thorax".into(),
            Part::Neck => "neck".into(),
            Part::Head => "head".into(),
            Part::Limb(side, limb) => format!("{}_{}", side.name(), limb.key()),
        }
    }

    /// Its name in `imubake inspect --json` and the sidecar: the key, but `spine` for the spine.
    pub fn id(self) -> String {
        match self {
            Part::Spine => "spine".into(),
            _ => self.key(),
        }
    }

    /// For people: `pelvis`, `left upper arm`.
    pub fn label(self) -> String {
        match self {
            Part::Pelvis => "pelvis".into(),
            Part::Spine => "spine".into(),
            Part::Neck => "neck".into(),
            Part::Head => "head".into(),
            Part::Limb(side, limb) => format!("{} {}", side.name(), limb.label()),
        }
    }
}

/// The keys a rig file's `segments:` may use: every part's, and `left_hand_end`/`right_hand_end`
/// (a point for `imubake angles`, not a part).
pub fn declarable_keys() -> Vec<String> {
    let mut keys: Vec<String> = Part::all().into_iter().map(Part::key).collect();
    keys.extend(Side::BOTH.map(|s| format!("{}_hand_end", s.name())));
    keys
}

/// How a part was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Found {
    /// The rig file's `segments:`.
    Declared,
    /// The joints' names.
    Named,
    /// The skeleton's shape (or its place between found parts).
    Shape,
}

impl Found {
    pub fn name(self) -> &'static str {
        match self {
            Found::Declared => "declared",
            Found::Named => "named",
            Found::Shape => "shape",
        }
    }
}

/// A part a feature needs and the skeleton lacks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{feature} needs the {part}, and no joint of `{skeleton}` is one (closest by name: {closest}); name it in a rig file's `segments: {{{key}: <joint>}}`"
)]
pub struct MissingPart {
    pub feature: String,
    pub skeleton: String,
    pub part: String,
    pub key: String,
    pub closest: String,
}

/// A skeleton as the resolution reads it: names, parents (each before its children), and the
/// rest pose's joint positions and End Sites (empty when unknown: then no shape is read).
#[derive(Debug, Clone)]
pub struct Skeleton<'a> {
    pub name: &'a str,
    pub names: Vec<&'a str>,
    pub parents: Vec<Option<usize>>,
    pub rest: Vec<Vector3<f64>>,
    pub end_sites: Vec<Option<Vector3<f64>>>,
    /// Declared parts: key → joint.
    pub declared: BTreeMap<String, usize>,
}

impl<'a> Skeleton<'a> {
    pub fn of_rig(rig: &'a Rig) -> Skeleton<'a> {
        Skeleton {
            name: rig.name(),
            names: rig.joints().iter().map(|j| j.name.as_str()).collect(),
            parents: rig.joints().iter().map(|j| j.parent).collect(),
            rest: rig.rest_positions(),
            end_sites: rig.joints().iter().map(|j| j.end_site).collect(),
            declared: rig.segments().clone(),
        }
    }
}

/// A skeleton's resolved parts.
#[derive(Debug, Clone, PartialEq)]
pub struct Anatomy {
    skeleton: String,
    names: Vec<String>,
    parents: Vec<Option<usize>>,
    /// Depth-first places and subtree sizes ([`depth_first`]).
    order: Vec<usize>,
    size: Vec<usize>,
    pelvis: Option<usize>,
    /// From the pelvis up; the last is the thorax.
    spine: Vec<usize>,
    /// From the thorax up.
    neck: Vec<usize>,
    head: Option<usize>,
    /// `[side][limb]`.
    limbs: [[Option<usize>; 8]; 2],
    found: BTreeMap<Part, Found>,
}

/// The hierarchy's relations, shared by the resolution's steps.
struct Tree<'s, 'a> {
    sk: &'s Skeleton<'a>,
    depth: Vec<usize>,
    children: Vec<Vec<usize>>,
    words: Vec<Option<(Option<Side>, Word)>>,
    /// Each joint's place in a depth-first order and its subtree's size (itself included), so
    /// that "below" is two comparisons: a skeleton of any size and depth costs no walk.
    order: Vec<usize>,
    size: Vec<usize>,
    /// The highest rest point (joints and End Sites) of each joint's subtree; empty without rest
    /// positions.
    highest: Vec<f64>,
}

/// Each joint's depth-first place and subtree size, from parents that come before their
/// children (others are ignored: the joint is a root).
fn depth_first(parents: &[Option<usize>]) -> (Vec<usize>, Vec<usize>) {
    let n = parents.len();
    let parent = |j: usize| parents[j].filter(|&p| p < j);
    let mut size = vec![1; n];
    for j in (0..n).rev() {
        if let Some(p) = parent(j) {
            size[p] += size[j];
        }
    }
    let mut order = vec![0; n];
    let mut next_root = 0;
    let mut next_child: Vec<usize> = vec![0; n];
    for j in 0..n {
        match parent(j) {
            None => {
                order[j] = next_root;
                next_root += size[j];
            }
            Some(p) => {
                order[j] = order[p] + 1 + next_child[p];
                next_child[p] += size[j];
            }
        }
    }
    (order, size)
}

impl Tree<'_, '_> {
    fn new<'s, 'a>(sk: &'s Skeleton<'a>) -> Tree<'s, 'a> {
        let n = sk.names.len();
        let mut depth = vec![0; n];
        let mut children = vec![Vec::new(); n];
        for j in 0..n {
            if let Some(p) = sk.parents[j].filter(|&p| p < j) {
                depth[j] = depth[p] + 1;
                children[p].push(j);
            }
        }
        let (order, size) = depth_first(&sk.parents);
        let mut highest = Vec::new();
        if sk.rest.len() == n && sk.end_sites.len() == n {
            highest = (0..n)
                .map(|j| {
                    let tip = sk.rest[j] + sk.end_sites[j].unwrap_or_default();
                    tip.y.max(sk.rest[j].y)
                })
                .collect();
            for j in (0..n).rev() {
                if let Some(p) = sk.parents[j].filter(|&p| p < j) {
                    highest[p] = highest[p].max(highest[j]);
                }
            }
        }
        Tree {
            sk,
            depth,
            children,
            words: sk.names.iter().map(|n| classify(n)).collect(),
            order,
            size,
            highest,
        }
    }

    fn parent(&self, j: usize) -> Option<usize> {
        self.sk.parents[j].filter(|&p| p < j)
    }

    /// Whether `j` lies strictly below `a`.
    fn below(&self, j: usize, a: usize) -> bool {
        self.order[a] < self.order[j] && self.order[j] < self.order[a] + self.size[a]
    }

    fn ancestors_or_self(&self, j: usize) -> Vec<usize> {
        let mut out = vec![j];
        let mut k = self.parent(j);
        while let Some(p) = k {
            out.push(p);
            k = self.parent(p);
        }
        out
    }

    fn common_ancestor(&self, a: usize, b: usize) -> Option<usize> {
        self.ancestors_or_self(b)
            .into_iter()
            .find(|&j| j == a || self.below(a, j))
    }

    /// The joints from `top` (exclusive) down to `bottom` (inclusive), top first; empty when
    /// `bottom` is not below `top`.
    fn path(&self, top: usize, bottom: usize) -> Vec<usize> {
        if !self.below(bottom, top) {
            return Vec::new();
        }
        let mut out: Vec<usize> = self
            .ancestors_or_self(bottom)
            .into_iter()
            .take_while(|&j| j != top)
            .collect();
        out.reverse();
        out
    }

    /// The joints on the way from `a` to `b` through the hierarchy (both excluded), in order:
    /// up from `a` to where they meet, then down to `b`. A pelvis below its spine (SlimeVR's
    /// recordings hang the body from the head) is walked up; where they meet, when it is
    /// neither, is left out (a centre of gravity above both the hips and the spine is no
    /// vertebra).
    fn way(&self, a: usize, b: usize) -> Vec<usize> {
        let Some(m) = self.common_ancestor(a, b) else {
            return Vec::new();
        };
        let mut out: Vec<usize> = if m == a {
            Vec::new()
        } else {
            self.ancestors_or_self(a)
                .into_iter()
                .skip(1)
                .take_while(|&j| j != m)
                .collect()
        };
        let mut down = self.path(m, b);
        down.pop();
        out.extend(down);
        out
    }

    /// Joints whose name says `word` on `side`, by depth then order.
    fn named(&self, side: Option<Side>, word: Word) -> Vec<usize> {
        let mut out: Vec<usize> = (0..self.words.len())
            .filter(|&j| self.words[j] == Some((side, word)))
            .collect();
        out.sort_by_key(|&j| (self.depth[j], j));
        out
    }

    fn has_shape(&self) -> bool {
        !self.sk.rest.is_empty()
    }

    /// Where a joint's bone ends: its first child, else its End Site.
    fn bone(&self, j: usize, next: Option<usize>) -> f64 {
        let rest = &self.sk.rest;
        match next.or_else(|| self.children[j].first().copied()) {
            Some(c) => (rest[c] - rest[j]).norm(),
            None => self.sk.end_sites[j].map_or(0.0, |e| e.norm()),
        }
    }

    /// The highest rest point (joints and End Sites) of `j`'s subtree.
    fn highest(&self, j: usize) -> f64 {
        self.highest[j]
    }

    fn tip(&self, j: usize) -> Vector3<f64> {
        self.sk.rest[j] + self.sk.end_sites[j].unwrap_or_default()
    }
}

impl Anatomy {
    /// A rig's anatomy.
    pub fn of(rig: &Rig) -> Anatomy {
        Anatomy::resolve(&Skeleton::of_rig(rig))
    }

    /// The anatomy of joint names alone (no hierarchy, no shape; a GLB's skin as the viewer
    /// reads it): the first joint named as each part.
    pub fn of_names<'a>(names: impl IntoIterator<Item = &'a str>) -> Anatomy {
        let names: Vec<&str> = names.into_iter().collect();
        let flat = Skeleton {
            name: "",
            parents: vec![None; names.len()],
            names,
            rest: Vec::new(),
            end_sites: Vec::new(),
            declared: BTreeMap::new(),
        };
        Anatomy::resolve(&flat)
    }

    /// The anatomy of any skeleton (see the module's docs).
    pub fn resolve(sk: &Skeleton) -> Anatomy {
        let t = Tree::new(sk);
        let flat = sk.parents.iter().all(Option::is_none) && sk.names.len() > 1;
        let mut found = BTreeMap::new();
        let declared = |part: Part| sk.declared.get(&part.key()).copied();
        // Below `a`, or anywhere when the hierarchy is unknown.
        let under = |j: usize, a: Option<usize>| match a {
            Some(a) => flat || t.below(j, a),
            None => true,
        };

        let mut limbs = [[None; 8]; 2];
        for side in Side::BOTH {
            let s = Some(side);
            let l = &mut limbs[side.index()];
            let set = |l: &mut [Option<usize>; 8],
                       limb: Limb,
                       j: usize,
                       how: Found,
                       found: &mut BTreeMap<Part, Found>| {
                l[limb.index()] = Some(j);
                found.insert(Part::Limb(side, limb), how);
            };
            let pick = |limb: Limb, words: &[usize], above: Option<usize>| {
                declared(Part::Limb(side, limb))
                    .map(|j| (j, Found::Declared))
                    .or_else(|| {
                        words
                            .iter()
                            .copied()
                            .find(|&j| under(j, above))
                            .map(|j| (j, Found::Named))
                    })
            };
            // Arms: `Shoulder` is the clavicle when an upper arm is below it.
            let upper_words = t.named(s, Word::UpperArm);
            let shoulders = t.named(s, Word::Shoulder);
            let is_clavicle = |j: usize| {
                if flat {
                    !upper_words.is_empty()
                } else {
                    upper_words.iter().any(|&u| t.below(u, j))
                }
            };
            let mut uppers = upper_words.clone();
            uppers.extend(shoulders.iter().copied().filter(|&j| !is_clavicle(j)));
            let upper = pick(Limb::UpperArm, &uppers, None);
            let mut clavicles = t.named(s, Word::Clavicle);
            clavicles.extend(shoulders.iter().copied().filter(|&j| is_clavicle(j)));
            let clavicle = declared(Part::Limb(side, Limb::Clavicle))
                .map(|j| (j, Found::Declared))
                .or_else(|| {
                    clavicles
                        .iter()
                        .copied()
                        .find(|&c| upper.is_none_or(|(u, _)| flat || t.below(u, c)))
                        .map(|j| (j, Found::Named))
                });
            let up = upper.map(|(j, _)| j);
            let forearm = pick(Limb::Forearm, &t.named(s, Word::Forearm), up);
            let hand = pick(
                Limb::Hand,
                &t.named(s, Word::Hand),
                forearm.map(|(j, _)| j).or(up),
            );
            // Legs: a sided `Hip` is a hip joint when a thigh is below it.
            let thigh_words = t.named(s, Word::Thigh);
            let mut thighs = thigh_words.clone();
            let hips = t.named(s, Word::Hip);
            thighs.extend(
                hips.iter().copied().filter(|&j| {
                    flat || !thigh_words.iter().chain(&hips).any(|&th| t.below(th, j))
                }),
            );
            let thigh = pick(Limb::Thigh, &thighs, None);
            let shank = pick(Limb::Shank, &t.named(s, Word::Shank), thigh.map(|(j, _)| j));
            let foot = pick(
                Limb::Foot,
                &t.named(s, Word::Foot),
                shank.or(thigh).map(|(j, _)| j),
            );
            // SlimeVR names the joint below the ankle `Foot`: a foot below the foot is the toes.
            let mut toe_words = t.named(s, Word::Toes);
            toe_words.extend(
                t.named(s, Word::Foot)
                    .into_iter()
                    .filter(|&j| !flat && foot.is_some_and(|(f, _)| t.below(j, f))),
            );
            let toes = pick(Limb::Toes, &toe_words, foot.map(|(j, _)| j));
            for (limb, j) in [
                (Limb::Clavicle, clavicle),
                (Limb::UpperArm, upper),
                (Limb::Forearm, forearm),
                (Limb::Hand, hand),
                (Limb::Thigh, thigh),
                (Limb::Shank, shank),
                (Limb::Foot, foot),
                (Limb::Toes, toes),
            ] {
                if let Some((j, how)) = j {
                    set(l, limb, j, how, &mut found);
                }
            }
            // A part missing between two found ones: the one joint between them.
            if !flat {
                for (a, m, b) in [
                    (Limb::UpperArm, Limb::Forearm, Limb::Hand),
                    (Limb::Thigh, Limb::Shank, Limb::Foot),
                ] {
                    if let (Some(ja), None, Some(jb)) = (l[a.index()], l[m.index()], l[b.index()]) {
                        let between = t.path(ja, jb);
                        if between.len() == 2 {
                            set(l, m, between[0], Found::Shape, &mut found);
                        }
                    }
                }
            }
        }

        if t.has_shape() && !flat {
            shape_limbs(&t, &mut limbs, &mut found);
        }

        let thighs = limbs.map(|l| l[Limb::Thigh.index()]);
        let pelvis = declared(Part::Pelvis)
            .map(|j| (j, Found::Declared))
            .or_else(|| match thighs {
                [Some(a), Some(b)] if !flat => t.common_ancestor(a, b).map(|j| (j, Found::Shape)),
                _ => None,
            })
            .or_else(|| {
                let one = thighs.iter().flatten().next().copied().filter(|_| !flat)?;
                // One thigh: the first joint above it that is not a hip joint.
                let mut p = t.parent(one)?;
                while matches!(t.words[p], Some((Some(_), Word::Hip))) {
                    p = t.parent(p)?;
                }
                Some((p, Found::Shape))
            })
            .or_else(|| {
                let named = t.named(None, Word::Pelvis);
                let roots = t.named(None, Word::Root);
                named.first().or(roots.first()).map(|&j| (j, Found::Named))
            })
            .or_else(|| (!flat && !sk.names.is_empty()).then_some((0, Found::Shape)));
        if let Some((j, how)) = pelvis {
            // Found where the thighs meet, and named so too: named.
            let named = matches!(t.words[j], Some((None, Word::Pelvis | Word::Root)));
            let how = if how == Found::Shape && named {
                Found::Named
            } else {
                how
            };
            found.insert(Part::Pelvis, how);
        }
        let pelvis = pelvis.map(|(j, _)| j);

        // The thorax: where the arms meet.
        let shoulder_of =
            |s: usize| limbs[s][Limb::Clavicle.index()].or(limbs[s][Limb::UpperArm.index()]);
        let thorax = declared(Part::Spine).or_else(|| {
            if flat {
                return None;
            }
            match (shoulder_of(0), shoulder_of(1)) {
                (Some(a), Some(b)) => t.common_ancestor(a, b),
                (Some(a), None) | (None, Some(a)) => t.parent(a),
                (None, None) => {
                    // No arms: the last joint named as the spine on the way from the pelvis to
                    // the head (which may be above it or, in SlimeVR's recordings, its ancestor),
                    // else up the pelvis's children.
                    let p = pelvis?;
                    if let Some(h) = t.named(None, Word::Head).first().copied() {
                        let way = t.way(p, h);
                        return way
                            .iter()
                            .copied()
                            .rev()
                            .find(|&j| matches!(t.words[j], Some((None, Word::Spine))));
                    }
                    let mut top = p;
                    while let Some(c) = t.children[top]
                        .iter()
                        .copied()
                        .find(|&c| matches!(t.words[c], Some((None, Word::Spine))))
                    {
                        top = c;
                    }
                    (top != p).then_some(top)
                }
            }
        });
        let spine = match (pelvis, thorax) {
            (Some(p), Some(th)) if th != p => {
                // Up from the pelvis, or through where both meet; the thorax included.
                let mut way = t.way(p, th);
                way.push(th);
                way
            }
            _ if flat => t.named(None, Word::Spine),
            _ => Vec::new(),
        };
        if !spine.is_empty() {
            let how = if declared(Part::Spine).is_some() {
                Found::Declared
            } else if spine
                .iter()
                .all(|&j| matches!(t.words[j], Some((None, Word::Spine))))
            {
                Found::Named
            } else {
                Found::Shape
            };
            found.insert(Part::Spine, how);
        }
        let top = spine.last().copied().or(pelvis);

        // The head: named, else the end of the chain rising between the arms.
        let on_arm =
            |j: usize| (0..2).any(|s| shoulder_of(s).is_some_and(|a| a == j || t.below(a, j)));
        let head = declared(Part::Head)
            .map(|j| (j, Found::Declared))
            .or_else(|| {
                let heads = t.named(None, Word::Head);
                heads
                    .iter()
                    .copied()
                    .find(|&h| under(h, top))
                    .or(heads.first().copied())
                    .map(|j| (j, Found::Named))
            })
            .or_else(|| {
                if flat || !t.has_shape() {
                    return None;
                }
                let top = top?;
                let mut j = t.children[top]
                    .iter()
                    .copied()
                    .filter(|&c| !on_arm(c) && !is_leg_root(&t, &limbs, c))
                    .max_by(|&a, &b| t.highest(a).total_cmp(&t.highest(b)))?;
                if t.highest(j) <= t.sk.rest[top].y {
                    return None;
                }
                // Up the chain to where it ends or branches (the eyes, or a head-top marker beside
                // them).
                while let [c] = t.children[j][..] {
                    j = c;
                }
                Some((j, Found::Shape))
            });
        if let Some((_, how)) = head {
            found.insert(Part::Head, how);
        }
        let head = head.map(|(j, _)| j);
        let neck = match (declared(Part::Neck), top, head) {
            (Some(n), _, Some(h)) if t.below(h, n) => {
                let mut chain = vec![n];
                chain.extend(t.path(n, h));
                chain.pop();
                chain
            }
            (Some(n), _, _) => vec![n],
            (None, Some(top), Some(h)) if !flat => t.way(top, h),
            _ => t.named(None, Word::Neck).into_iter().take(1).collect(),
        };
        if !neck.is_empty() {
            let how = if declared(Part::Neck).is_some() {
                Found::Declared
            } else if neck
                .iter()
                .all(|&j| matches!(t.words[j], Some((None, Word::Neck))))
            {
                Found::Named
            } else {
                Found::Shape
            };
            found.insert(Part::Neck, how);
        }
        Anatomy {
            skeleton: sk.name.to_string(),
            names: sk.names.iter().map(|s| s.to_string()).collect(),
            parents: sk.parents.clone(),
            order: t.order.clone(),
            size: t.size.clone(),
            pelvis,
            spine,
            neck,
            head,
            limbs,
            found,
        }
    }

    pub fn pelvis(&self) -> Option<usize> {
        self.pelvis
    }

    /// The spine from the pelvis up (the pelvis not included); the last is the thorax.
    pub fn spine(&self) -> &[usize] {
        &self.spine
    }

    /// The top of the spine, where the arms meet.
    pub fn thorax(&self) -> Option<usize> {
        self.spine.last().copied()
    }

    /// The neck from the thorax up (neither included).
    pub fn neck(&self) -> &[usize] {
        &self.neck
    }

    pub fn head(&self) -> Option<usize> {
        self.head
    }

    pub fn limb(&self, side: Side, limb: Limb) -> Option<usize> {
        self.limbs[side.index()][limb.index()]
    }

    /// `[left, right]` feet, when both are found.
    pub fn feet(&self) -> Option<[usize; 2]> {
        Some([
            self.limb(Side::Left, Limb::Foot)?,
            self.limb(Side::Right, Limb::Foot)?,
        ])
    }

    /// The part's joints: one, none, or a chain (the spine and the neck, from the bottom up).
    pub fn joints(&self, part: Part) -> Vec<usize> {
        match part {
            Part::Pelvis => self.pelvis.into_iter().collect(),
            Part::Spine => self.spine.clone(),
            Part::Neck => self.neck.clone(),
            Part::Head => self.head.into_iter().collect(),
            Part::Limb(side, limb) => self.limb(side, limb).into_iter().collect(),
        }
    }

    /// How the part was found; `None` when it was not.
    pub fn found(&self, part: Part) -> Option<Found> {
        self.found.get(&part).copied()
    }

    /// The part a joint is (a chain's every joint is its part).
    pub fn part_of(&self, joint: usize) -> Option<Part> {
        Part::all()
            .into_iter()
            .find(|&p| self.joints(p).contains(&joint))
    }

    /// The joint names.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Whether `joint` lies strictly below `ancestor`.
    pub fn is_below(&self, joint: usize, ancestor: usize) -> bool {
        match (self.order.get(joint), self.order.get(ancestor)) {
            (Some(&j), Some(&a)) => a < j && j < a + self.size[ancestor],
            _ => false,
        }
    }

    /// A joint's parent (one that comes before it).
    pub fn parent(&self, joint: usize) -> Option<usize> {
        self.parents
            .get(joint)
            .copied()
            .flatten()
            .filter(|&p| p < joint)
    }

    /// The spine's three slots of Mixamo's and Unity's skeletons (`Spine`, `Spine1`/`Chest`,
    /// `Spine2`/`UpperChest`): one joint is the first, two the first two, more the first, the
    /// middle (index n / 2) and the top.
    fn spine_slots(&self) -> Vec<usize> {
        let s = &self.spine;
        match s.len() {
            0..=2 => s.clone(),
            n => vec![s[0], s[n / 2], s[n - 1]],
        }
    }

    /// Each found part's joint under Mixamo's names (`Hips`, `Spine`, `Spine1`, `Spine2`,
    /// `Neck`, `Head`, `LeftShoulder` (the clavicle), `LeftArm`, `LeftForeArm`, `LeftHand`,
    /// `LeftUpLeg`, `LeftLeg`, `LeftFoot`, `LeftToeBase`, …); a chain's slots as in
    /// [`Anatomy::unity_bones`].
    pub fn mixamo_slots(&self) -> Vec<(String, usize)> {
        self.slots(|l| l.names().0, ["Spine", "Spine1", "Spine2"])
    }

    /// Each found part's joint under Unity's humanoid bone names (VMC's): `Hips`, `Spine`,
    /// `Chest`, `UpperChest`, `Neck` (the neck's first joint), `Head`, `LeftShoulder`,
    /// `LeftUpperArm`, `LeftLowerArm`, `LeftHand`, `LeftUpperLeg`, `LeftLowerLeg`, `LeftFoot`,
    /// `LeftToes`, ….
    pub fn unity_bones(&self) -> Vec<(String, usize)> {
        self.slots(|l| l.names().1, ["Spine", "Chest", "UpperChest"])
    }

    fn slots(&self, limb_name: fn(Limb) -> &'static str, spine: [&str; 3]) -> Vec<(String, usize)> {
        let mut out: Vec<(String, usize)> = Vec::new();
        out.extend(self.pelvis.map(|j| ("Hips".to_string(), j)));
        for (name, j) in spine.iter().zip(self.spine_slots()) {
            out.push((name.to_string(), j));
        }
        out.extend(self.neck.first().map(|&j| ("Neck".to_string(), j)));
        out.extend(self.head.map(|j| ("Head".to_string(), j)));
        for side in Side::BOTH {
            for limb in Limb::ALL {
                if let Some(j) = self.limb(side, limb) {
                    out.push((format!("{}{}", side.prefix(), limb_name(limb)), j));
                }
            }
        }
        out
    }

    /// `Ok` when every part is found; else the first missing one, with the joints whose names
    /// come closest to it.
    pub fn require(&self, parts: &[Part], feature: &str) -> Result<(), MissingPart> {
        match parts.iter().find(|&&p| self.joints(p).is_empty()) {
            None => Ok(()),
            Some(&part) => Err(MissingPart {
                feature: feature.to_string(),
                skeleton: self.skeleton.clone(),
                part: part.label(),
                key: part.key(),
                closest: self.closest(part, 3).join(", "),
            }),
        }
    }

    /// The `n` joint names closest to the part's names (Jaro–Winkler against Mixamo's, Unity's
    /// and the part's own), best first.
    pub fn closest(&self, part: Part, n: usize) -> Vec<String> {
        let targets: Vec<String> = match part {
            Part::Pelvis => vec!["hips".into(), "pelvis".into()],
            Part::Spine => vec!["spine".into(), "chest".into()],
            Part::Neck => vec!["neck".into()],
            Part::Head => vec!["head".into()],
            Part::Limb(side, limb) => {
                let (m, u) = limb.names();
                vec![
                    format!("{}{m}", side.prefix()).to_lowercase(),
                    format!("{}{u}", side.prefix()).to_lowercase(),
                    format!("{}{}", side.name(), limb.label().replace(' ', "")),
                ]
            }
        };
        let mut scored: Vec<(f64, &String)> = self
            .names
            .iter()
            .map(|name| {
                let bare = name
                    .rsplit([':', '|'])
                    .next()
                    .unwrap_or(name)
                    .to_lowercase();
                let score = targets
                    .iter()
                    .map(|t| strsim::jaro_winkler(&bare, t))
                    .fold(0.0, f64::max);
                (score, name)
            })
            .collect();
        scored.sort_by(|a, b| b.0.total_cmp(&a.0));
        scored.into_iter().take(n).map(|(_, s)| s.clone()).collect()
    }

    /// `{"skeleton": …, "parts": {"<id>": {"joints": [names], "found": "named" | … | null}}}`,
    /// every part in [`Part::all`]'s order.
    pub fn to_json(&self) -> serde_json::Value {
        let mut parts = serde_json::Map::new();
        for part in Part::all() {
            let joints: Vec<&str> = self
                .joints(part)
                .iter()
                .map(|&j| self.names[j].as_str())
                .collect();
            parts.insert(
                part.id(),
                serde_json::json!({"joints": joints, "found": self.found(part).map(Found::name)}),
            );
        }
        serde_json::json!({"skeleton": self.skeleton, "parts": parts})
    }

    /// One line per part: its key, its joint(s) and how each was found; `-` where none.
    pub fn describe(&self) -> Vec<String> {
        Part::all()
            .into_iter()
            .map(|part| {
                let joints = self.joints(part);
                let label = part.label();
                if joints.is_empty() {
                    return format!("{label:<16} -");
                }
                let names: Vec<&str> = joints.iter().map(|&j| self.names[j].as_str()).collect();
                let how = self.found(part).map_or("", Found::name);
                format!("{label:<16} {} ({how})", names.join(" → "))
            })
            .collect()
    }
}

/// Whether `j` starts a leg (a thigh, or a joint a thigh hangs from).
fn is_leg_root(t: &Tree, limbs: &[[Option<usize>; 8]; 2], j: usize) -> bool {
    limbs
        .iter()
        .any(|l| l[Limb::Thigh.index()].is_some_and(|th| th == j || t.below(th, j)))
}

/// Limbs the names said nothing of, from the skeleton's shape (see the module's docs).
fn shape_limbs(t: &Tree, limbs: &mut [[Option<usize>; 8]; 2], found: &mut BTreeMap<Part, Found>) {
    let n = t.sk.names.len();
    let centre = t.sk.rest[0].x;
    let known = |limbs: &[[Option<usize>; 8]; 2], j: usize| {
        limbs
            .iter()
            .flatten()
            .flatten()
            .any(|&p| p == j || t.below(j, p))
    };
    let leaves: Vec<usize> = (0..n).filter(|&j| t.children[j].is_empty()).collect();
    let side_of = |j: usize| {
        let x = t.tip(j).x - centre;
        if x > 1e-9 {
            Some(Side::Left)
        } else if x < -1e-9 {
            Some(Side::Right)
        } else {
            None
        }
    };
    let empty = |limbs: &[[Option<usize>; 8]; 2], side: Side, parts: &[Limb]| {
        parts
            .iter()
            .all(|l| limbs[side.index()][l.index()].is_none())
    };
    let leg = [Limb::Thigh, Limb::Shank, Limb::Foot, Limb::Toes];
    let arm = [Limb::Clavicle, Limb::UpperArm, Limb::Forearm, Limb::Hand];
    // Legs: the lowest leaf on each side.
    let lowest = |side: Side, limbs: &[[Option<usize>; 8]; 2]| {
        leaves
            .iter()
            .copied()
            .filter(|&j| side_of(j) == Some(side) && !known(limbs, j))
            .min_by(|&a, &b| t.tip(a).y.total_cmp(&t.tip(b).y))
    };
    let leg_leaves = Side::BOTH.map(|s| lowest(s, limbs));
    for side in Side::BOTH {
        if !empty(limbs, side, &leg) {
            continue;
        }
        let Some(leaf) = leg_leaves[side.index()] else {
            continue;
        };
        // Where the leg starts: the other leg's top, or where the two leaves meet.
        let other = side.index() ^ 1;
        let hip = limbs[other][Limb::Thigh.index()]
            .and_then(|th| t.parent(th))
            .filter(|&h| t.below(leaf, h))
            .or_else(|| leg_leaves[other].and_then(|o| t.common_ancestor(leaf, o)));
        let Some(hip) = hip else { continue };
        assign_chain(t, &t.path(hip, leaf), side, &leg, false, limbs, found);
    }
    // Arms: the leaf furthest out on each side, not in a leg.
    let outermost = |side: Side, limbs: &[[Option<usize>; 8]; 2]| {
        leaves
            .iter()
            .copied()
            .filter(|&j| side_of(j) == Some(side) && !known(limbs, j))
            .max_by(|&a, &b| {
                (t.tip(a).x - centre)
                    .abs()
                    .total_cmp(&(t.tip(b).x - centre).abs())
            })
    };
    let arm_leaves = Side::BOTH.map(|s| outermost(s, limbs));
    for side in Side::BOTH {
        if !empty(limbs, side, &arm) {
            continue;
        }
        let Some(leaf) = arm_leaves[side.index()] else {
            continue;
        };
        let other = side.index() ^ 1;
        let base = limbs[other][Limb::Clavicle.index()]
            .or(limbs[other][Limb::UpperArm.index()])
            .and_then(|a| t.parent(a))
            .filter(|&b| t.below(leaf, b))
            .or_else(|| arm_leaves[other].and_then(|o| t.common_ancestor(leaf, o)));
        let Some(base) = base else { continue };
        assign_chain(t, &t.path(base, leaf), side, &arm, true, limbs, found);
    }
}

/// A limb's parts along `chain` (from the body out): the upper arm (thigh) starts the two
/// longest consecutive bones — or, in an arm that branches into fingers, the second joint with a
/// bone of its own above the hand —; the joint before it is the clavicle (arms only); the rest
/// follow.
fn assign_chain(
    t: &Tree,
    chain: &[usize],
    side: Side,
    parts: &[Limb; 4],
    arm: bool,
    limbs: &mut [[Option<usize>; 8]; 2],
    found: &mut BTreeMap<Part, Found>,
) {
    if chain.len() < 2 {
        return;
    }
    let bones: Vec<f64> = chain
        .iter()
        .enumerate()
        .map(|(i, &j)| t.bone(j, chain.get(i + 1).copied()))
        .collect();
    let longest = (0..chain.len() - 1)
        .max_by(|&a, &b| (bones[a] + bones[a + 1]).total_cmp(&(bones[b] + bones[b + 1])))
        .unwrap_or(0);
    // An arm that branches into fingers: the hand is where it branches (or the joint it sits on,
    // CMU's `LeftFingerBase` on `LeftHand`), and the forearm and upper arm the two joints with a
    // bone of their own above it — a clavicle can be as long as a forearm (CMU's), lengths alone
    // do not tell.
    let hand = arm
        .then(|| {
            // The last branch: twist helpers branch off the upper arm and forearm before it.
            let b = chain.iter().rposition(|&j| t.children[j].len() > 1)?;
            let eps = 1e-9 * (1.0 + t.sk.rest[chain[b]].norm());
            let sits = b > 0 && (t.sk.rest[chain[b]] - t.sk.rest[chain[b - 1]]).norm() <= eps;
            Some(if sits { b - 1 } else { b })
        })
        .flatten();
    let start = match hand {
        Some(h) => {
            let long: Vec<usize> = (0..h).rev().filter(|&i| bones[i] > 1e-9).take(2).collect();
            match long.as_slice() {
                [_, upper] => *upper,
                _ => longest,
            }
        }
        None => longest,
    };
    let (first, rest): (Option<Limb>, &[Limb]) = if arm {
        (Some(parts[0]), &parts[1..])
    } else {
        (None, &parts[..])
    };
    let mut set = |limb: Limb, j: usize| {
        limbs[side.index()][limb.index()] = Some(j);
        found.insert(Part::Limb(side, limb), Found::Shape);
    };
    if let Some(clavicle) = first
        && start > 0
    {
        set(clavicle, chain[start - 1]);
    }
    for (k, &limb) in rest.iter().enumerate() {
        if let Some(&j) = chain.get(start + k) {
            set(limb, j);
        }
    }
}

/// `(source joint, target joint)` pairs of the parts both skeletons have: one joint per part,
/// and along the spine and the neck each target joint paired with the source joint at the same
/// place along the chain (the first with the first, the top with the top, between by rounding
/// i·(n−1)/(m−1); a target chain of one joint takes the source's top).
pub fn pairs(source: &Anatomy, target: &Anatomy) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for part in Part::all() {
        let s = source.joints(part);
        let t = target.joints(part);
        if s.is_empty() || t.is_empty() {
            continue;
        }
        let (n, m) = (s.len(), t.len());
        for (i, &tj) in t.iter().enumerate() {
            let k = if m == 1 {
                n - 1
            } else {
                ((i * (n - 1)) as f64 / (m - 1) as f64).round() as usize
            };
            out.push((s[k.min(n - 1)], tj));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::load_rig;

    fn named(a: &Anatomy, j: Option<usize>) -> Option<&str> {
        j.map(|j| a.names()[j].as_str())
    }

    #[test]
    fn mixamo_and_sou12_resolve_every_part() {
        let rig = load_rig("mixamo").unwrap();
        let a = Anatomy::of(&rig);
        let slots: Vec<(String, String)> = a
            .mixamo_slots()
            .into_iter()
            .map(|(s, j)| (s, a.names()[j].clone()))
            .collect();
        assert_eq!(slots.len(), 22);
        assert!(slots.iter().all(|(s, n)| s == n), "{slots:?}");
        assert_eq!(
            a.found(Part::Limb(Side::Left, Limb::Clavicle)),
            Some(Found::Named)
        );
        let sou = load_rig("sou12").unwrap();
        let a = Anatomy::of(&sou);
        assert_eq!(named(&a, a.pelvis()), Some("N0_0"));
        assert_eq!(named(&a, a.thorax()), Some("N0_1"));
        assert_eq!(named(&a, a.limb(Side::Left, Limb::UpperArm)), Some("N2_0"));
        assert_eq!(named(&a, a.limb(Side::Right, Limb::Shank)), Some("N3_1"));
        assert_eq!(named(&a, a.head()), Some("N5_1"));
        assert_eq!(a.neck().len(), 1);
        assert_eq!(a.limb(Side::Left, Limb::Hand), None);
        assert_eq!(a.limb(Side::Left, Limb::Foot), None);
    }

    /// With every name replaced by `j0`, `j1`, … only the shape decides, and it finds Mixamo's
    /// parts where its names put them.
    #[test]
    fn the_shape_alone_finds_the_parts_names_find() {
        let rig = load_rig("mixamo").unwrap();
        let named = Anatomy::of(&rig);
        let mut sk = Skeleton::of_rig(&rig);
        let stripped: Vec<String> = (0..rig.len()).map(|i| format!("j{i}")).collect();
        sk.names = stripped.iter().map(String::as_str).collect();
        let shape = Anatomy::resolve(&sk);
        for part in Part::all() {
            assert_eq!(shape.joints(part), named.joints(part), "{}", part.label());
        }
        assert_eq!(
            shape.found(Part::Limb(Side::Left, Limb::Thigh)),
            Some(Found::Shape)
        );
    }

    #[test]
    fn a_missing_part_names_itself_and_the_closest_joints() {
        let sou = load_rig("sou12").unwrap();
        let e = Anatomy::of(&sou)
            .require(&[Part::Limb(Side::Left, Limb::Foot)], "--root feet")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--root feet needs the left foot, and no joint of `sou12` is one"),
            "{e}"
        );
        assert!(e.contains("`segments: {left_foot: <joint>}`"), "{e}");
        let text = "name: odd\njoints:\n  - {name: Hips, offset: [0, 1, 0]}\n  - {name: LeftFootIK, parent: Hips, offset: [0.1, -0.9, 0]}\n";
        let rig = crate::rig::file::parse_rig(text, std::path::Path::new("odd.yaml")).unwrap();
        let e = Anatomy::of(&rig)
            .require(&[Part::Limb(Side::Left, Limb::Foot)], "--root feet")
            .unwrap_err()
            .to_string();
        assert!(e.contains("closest by name: LeftFootIK, Hips"), "{e}");
    }

    /// SlimeVR's legs: `Left-Hip` the thigh, `Left-Knee` the shank, `Left-Ankle` the foot and
    /// `Left-Foot`, below it, the toes; CMU's `LHipJoint` above `LeftUpLeg` stays a hip joint.
    #[test]
    fn ambiguous_words_are_decided_down_the_leg() {
        let text = "name: legs\njoints:\n  - {name: Hip, offset: [0, 1, 0]}\n  - {name: LHipJoint, parent: Hip, offset: [0, 0, 0]}\n  - {name: Left-Hip, parent: LHipJoint, offset: [0.1, -0.05, 0]}\n  - {name: Left-Knee, parent: Left-Hip, offset: [0, -0.45, 0]}\n  - {name: Left-Ankle, parent: Left-Knee, offset: [0, -0.45, 0]}\n  - {name: Left-Foot, parent: Left-Ankle, offset: [0, -0.05, 0.12], end_site: [0, 0, 0.05]}\n";
        let rig = crate::rig::file::parse_rig(text, std::path::Path::new("legs.yaml")).unwrap();
        let a = Anatomy::of(&rig);
        let part = |l: Limb| named(&a, a.limb(Side::Left, l));
        assert_eq!(part(Limb::Thigh), Some("Left-Hip"));
        assert_eq!(part(Limb::Shank), Some("Left-Knee"));
        assert_eq!(part(Limb::Foot), Some("Left-Ankle"));
        assert_eq!(part(Limb::Toes), Some("Left-Foot"));
    }

    /// A chain of 200 000 joints (no name says anything, so the shape is read down all of it)
    /// and 3 000 sided `Hip` joints in a row resolve without recursion or a walk per pair.
    #[test]
    fn deep_and_hostile_skeletons_resolve() {
        let n: usize = 200_000;
        let names: Vec<String> = (0..n).map(|i| format!("j{i}")).collect();
        let sk = Skeleton {
            name: "deep",
            names: names.iter().map(String::as_str).collect(),
            parents: (0..n).map(|i| i.checked_sub(1)).collect(),
            rest: (0..n).map(|i| Vector3::new(0.0, i as f64, 0.0)).collect(),
            end_sites: vec![None; n],
            declared: BTreeMap::new(),
        };
        let a = Anatomy::resolve(&sk);
        assert!(a.limb(Side::Left, Limb::Thigh).is_none());
        let n: usize = 3_000;
        let mut names = vec!["Hips".to_string()];
        names.extend((1..n).map(|i| format!("ns{i}:LeftHip")));
        let sk = Skeleton {
            name: "hips",
            names: names.iter().map(String::as_str).collect(),
            parents: (0..n).map(|i| i.checked_sub(1)).collect(),
            rest: (0..n)
                .map(|i| Vector3::new(0.1, -(i as f64), 0.0))
                .collect(),
            end_sites: vec![None; n],
            declared: BTreeMap::new(),
        };
        let a = Anatomy::resolve(&sk);
        // The deepest Hip, with no Hip below it, is the thigh.
        assert_eq!(a.limb(Side::Left, Limb::Thigh), Some(n - 1));
    }

    /// An Unreal-like skeleton with its names stripped: twist helpers branch off the upper arm
    /// and the forearm, the fingers off the hand; the hand is where the arm last branches.
    #[test]
    fn twist_helpers_do_not_pass_for_the_hand() {
        let (mut parents, mut rest) = (Vec::new(), Vec::new());
        let mut add = |p: Option<usize>, x: f64, y: f64, z: f64| {
            parents.push(p);
            rest.push(Vector3::new(x, y, z));
            parents.len() - 1
        };
        let root = add(None, 0.0, 0.0, 0.0);
        let pelvis = add(Some(root), 0.0, 1.0, 0.0);
        let spine = add(Some(pelvis), 0.0, 1.4, 0.0);
        add(Some(spine), 0.0, 1.7, 0.0);
        let mut arm = Vec::new();
        for sx in [1.0, -1.0] {
            let c = add(Some(spine), 0.05 * sx, 1.45, 0.0);
            let u = add(Some(c), 0.2 * sx, 1.45, 0.0);
            add(Some(u), 0.3 * sx, 1.45, 0.0);
            let l = add(Some(u), 0.48 * sx, 1.45, 0.0);
            add(Some(l), 0.6 * sx, 1.45, 0.0);
            let h = add(Some(l), 0.74 * sx, 1.45, 0.0);
            let f = add(Some(h), 0.8 * sx, 1.45, 0.02);
            add(Some(f), 0.84 * sx, 1.45, 0.02);
            let g = add(Some(h), 0.8 * sx, 1.45, -0.02);
            add(Some(g), 0.83 * sx, 1.45, -0.02);
            let th = add(Some(pelvis), 0.1 * sx, 0.95, 0.0);
            let k = add(Some(th), 0.1 * sx, 0.5, 0.0);
            let fo = add(Some(k), 0.1 * sx, 0.08, 0.0);
            add(Some(fo), 0.1 * sx, 0.0, 0.1);
            arm.push([c, u, l, h]);
        }
        let names: Vec<String> = (0..parents.len()).map(|i| format!("j{i}")).collect();
        let a = Anatomy::resolve(&Skeleton {
            name: "stripped",
            names: names.iter().map(String::as_str).collect(),
            end_sites: vec![None; parents.len()],
            parents,
            rest,
            declared: BTreeMap::new(),
        });
        let [c, u, l, h] = arm[0];
        let got = [Limb::Clavicle, Limb::UpperArm, Limb::Forearm, Limb::Hand]
            .map(|limb| a.limb(Side::Left, limb));
        assert_eq!(got, [Some(c), Some(u), Some(l), Some(h)]);
        assert_eq!(a.pelvis(), Some(pelvis));
    }

    #[test]
    fn chains_pair_by_their_place_along_them() {
        let mk = |spine: usize| {
            let mut names = vec!["Hips".to_string()];
            names.extend((0..spine).map(|i| format!("torso_{}", i + 1)));
            let parents: Vec<Option<usize>> = (0..names.len()).map(|i| i.checked_sub(1)).collect();
            (names, parents)
        };
        let anat = |spine: usize| {
            let (names, parents) = mk(spine);
            let refs: Vec<&str> = names.iter().map(String::as_str).collect();
            Anatomy::resolve(&Skeleton {
                name: "chain",
                names: refs,
                parents,
                rest: Vec::new(),
                end_sites: Vec::new(),
                declared: BTreeMap::new(),
            })
        };
        let (seven, three) = (anat(7), anat(3));
        assert_eq!(seven.spine(), &[1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(seven.spine_slots(), vec![1, 4, 7]);
        let p = pairs(&seven, &three);
        assert_eq!(p, vec![(0, 0), (1, 1), (4, 2), (7, 3)]);
    }
}
