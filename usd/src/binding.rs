//! UsdShade material binding resolution, as pxr's
//! `UsdShadeMaterialBindingAPI::ComputeBoundMaterial(materialPurpose = "full")` resolves it
//! (checked against usd-core 26.11 by `tests/usd/test_bindings.py`).
//!
//! The renderer draws the `full` purpose. Two passes walk the bound prim and its ancestors,
//! nearest first: the first considers only `full` bindings, and only when it finds none
//! anywhere does the second consider the all-purpose ones. `material:binding:preview` and
//! other purposes are never read.
//!
//! | at each prim of the chain, in this order | taken when |
//! |---|---|
//! | the direct binding: `material:binding:full` (pass 1) or `material:binding` (pass 2) — pxr reads `material:binding` in pass 2 only where the prim has no `material:binding:full` with one prim target | nothing was found nearer, or the relationship is `bindMaterialAs = "strongerThanDescendants"` |
//! | the collection bindings `material:binding:collection:full:NAME` (pass 1) or `material:binding:collection:NAME` (pass 2), in dictionary order of NAME (`TfDictionaryLessThan`: case-insensitive, digit runs by value, not the authored order), the first whose collection includes the bound prim | nothing was found nearer, the binding taken so far is this prim's direct binding, or the relationship is `strongerThanDescendants` |
//!
//! A binding taken replaces any taken nearer, so the outermost `strongerThanDescendants`
//! binding wins. Collection membership (`UsdCollectionAPI`, relationship mode) is openusd's
//! rule map (`Collection::compute_membership_query`: `includes` with the `expansionRule`,
//! `excludes`, `includeRoot`, `includes` of other collections merged, cycles broken) read as
//! pxr's `IsPathIncluded` reads it: the nearest opinion on the prim or an ancestor decides,
//! `exclude` excludes, `expandPrims` (the default) and `expandPrimsAndProperties` include, and
//! `explicitOnly` includes the listed prim itself only, an ancestor's being passed over for the
//! next opinion up (openusd's own `is_path_included` stops there).
//!
//! Prims of a native instance's prototype continue their chain through the instance prim and
//! its ancestors (instance proxies, [`InheritedBinding`]); a collection outside the instance is
//! asked about the proxy's path. A prototype is walked once per [`BindingKey`]. A `GeomSubset`
//! resolves as any prim (its chain runs through its mesh).
//!
//! | malformed binding | pxr | here |
//! |---|---|---|
//! | direct binding without exactly one prim target | ignored | ignored, with a warning |
//! | collection binding without one collection and one prim target | ignored | ignored, with a warning |
//! | collection target that is not a prim's applied `CollectionAPI:NAME` | ignored | ignored, with a warning |
//! | collection in `membershipExpression` mode | evaluated | not evaluated (includes nothing), with a warning |
//! | target (direct or collection) that is not a Material prim | wins, then binds no material | wins, renders magenta with a warning ([`crate::shading`]) |

use crate::value::{attr_error, layer_of_prim};
use crate::Error;
use openusd::usd::{is_collection_api_path, Collection, MembershipQuery, PathRule};
use openusd::{sdf, usd};
use std::cmp::Ordering;
use std::collections::HashMap;
use std::rc::Rc;

/// The direct binding relationships, full purpose first.
const DIRECT: [(&str, Purpose); 2] = [("material:binding:full", Purpose::Full), ("material:binding", Purpose::All)];
/// The all-purpose collection binding prefix (`…:NAME`, NAME without a namespace).
const COLLECTION_ALL: &str = "material:binding:collection:";
/// The full-purpose collection binding prefix.
const COLLECTION_FULL: &str = "material:binding:collection:full:";

/// A binding's material purpose, in the order the passes consider them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Purpose {
    /// `full`.
    Full,
    /// All-purpose (no purpose in the relationship's name).
    All,
}

/// A direct binding: its material path, purpose and strength.
#[derive(Debug)]
struct Direct {
    material: sdf::Path,
    purpose: Purpose,
    stronger: bool,
}

/// A collection binding: the collection's membership, its material path and strength.
#[derive(Debug)]
struct CollectionBinding {
    query: MembershipQuery,
    material: sdf::Path,
    stronger: bool,
}

/// The bindings authored on one prim that purpose `full` reads (pxr's `BindingsAtPrim`).
#[derive(Debug, Default)]
struct PrimBindings {
    direct: Option<Direct>,
    full: Vec<CollectionBinding>,
    all: Vec<CollectionBinding>,
}

impl PrimBindings {
    fn collections(&self, purpose: Purpose) -> &[CollectionBinding] {
        match purpose {
            Purpose::Full => &self.full,
            Purpose::All => &self.all,
        }
    }
}

/// The bindings a native instance prim and its ancestors pass to the prims of its prototype
/// (pxr resolves an instance proxy's binding along the proxy's path, which runs through the
/// instance prim): the chain beyond the prototype and the key prototypes are shared by.
#[derive(Debug, Clone, Default)]
pub struct InheritedBinding {
    /// The chain beyond the prototype, nearest first: a prim whose bindings are read, and the
    /// instance's path in that prim's namespace (where its collections name prims).
    levels: Vec<(sdf::Path, sdf::Path)>,
    /// The root of the prototype being walked (its prims' own chains stop below it).
    prototype: Option<sdf::Path>,
    /// What the levels decide for the prototype's prims.
    key: BindingKey,
}

/// What an instance's chain decides for its prototype's prims: prototypes walked (and meshes
/// built) for one key serve every instance with that key.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub enum BindingKey {
    /// Outside native instances.
    #[default]
    Stage,
    /// The same for every prim of the prototype: per pass (full, all), the binding the chain
    /// gives a prim with nothing nearer, and the one overriding a nearer binding (stronger).
    Uniform([Option<sdf::Path>; 4]),
    /// A collection on the chain has opinions on prims inside the instance: the chain's
    /// bindings as seen from inside the instance (materials, purposes, strengths, and each
    /// collection's opinions relative to the instance), shared by instances that see the same.
    Relative(String),
}

impl InheritedBinding {
    /// The key prototypes and meshes built under these bindings are cached by.
    pub fn key(&self) -> &BindingKey {
        &self.key
    }
}

/// pxr's walk for one purpose: whether a binding was taken, its material, and the chain
/// position of the prim it is on (None: a prim nearer than the levels walked).
#[derive(Debug, Default)]
struct Walk {
    taken: bool,
    material: Option<sdf::Path>,
    at: Option<usize>,
}

impl Walk {
    /// One prim of the chain (position `at`), `member`: whether a collection includes the
    /// bound prim.
    fn step(&mut self, at: usize, b: &PrimBindings, purpose: Purpose, member: &dyn Fn(&MembershipQuery) -> bool) {
        // the direct binding, then the first collection binding that includes the prim
        if let Some(d) = b.direct.as_ref().filter(|d| d.purpose == purpose) {
            if !self.taken || d.stronger {
                self.take(at, &d.material);
            }
        }
        for c in b.collections(purpose) {
            if member(&c.query) && (!self.taken || self.at == Some(at) || c.stronger) {
                self.take(at, &c.material);
                break;
            }
        }
    }

    /// Takes the binding to `material` on the prim at chain position `at`.
    fn take(&mut self, at: usize, material: &sdf::Path) {
        self.taken = true;
        self.material = Some(material.clone());
        self.at = Some(at);
    }
}

/// Reads and caches each prim's bindings; resolves bound materials.
#[derive(Default)]
pub struct Resolver {
    by_prim: HashMap<sdf::Path, Rc<PrimBindings>>,
}

impl Resolver {
    /// The material path bound to `prim` for purpose `full` (see the module docs), with the
    /// chain beyond a native prototype that `outer` carries. Malformed bindings are warned
    /// about once.
    pub fn bound_material(
        &mut self,
        prim: &usd::Prim,
        outer: &InheritedBinding,
        warnings: &mut Vec<String>,
    ) -> Result<Option<sdf::Path>, Error> {
        // the prim's own chain (stopping below the prototype root), then the instance's
        let stage = prim.stage();
        let mut inner = Vec::new();
        for p in prim.path().ancestors_below_root() {
            if outer.prototype.as_ref() == Some(&p) {
                break;
            }
            inner.push(self.read(&stage.prim(p), warnings)?);
        }
        let mut levels = Vec::new();
        for (p, root) in &outer.levels {
            let b = self.read(&stage.prim(p.clone()), warnings)?;
            let path = match &outer.prototype {
                Some(proto) => prim.path().replace_prefix(proto, root).unwrap_or_else(|| root.clone()),
                None => prim.path().clone(),
            };
            levels.push((b, path));
        }
        // the passes: full, then all-purpose
        for purpose in [Purpose::Full, Purpose::All] {
            let mut walk = Walk::default();
            for (i, b) in inner.iter().enumerate() {
                walk.step(i, b, purpose, &|q| includes(q, prim.path()));
            }
            for (j, (b, path)) in levels.iter().enumerate() {
                walk.step(inner.len() + j, b, purpose, &|q| includes(q, path));
            }
            if walk.taken {
                return Ok(walk.material);
            }
        }
        Ok(None)
    }

    /// The bindings the prototype `prototype` of the native instance `instance` inherits:
    /// `instance`'s chain in its own namespace (stopping below `outer`'s prototype root),
    /// then `outer`'s levels (nested instancing).
    pub fn enter(
        &mut self,
        outer: &InheritedBinding,
        instance: &usd::Prim,
        prototype: &sdf::Path,
        warnings: &mut Vec<String>,
    ) -> Result<InheritedBinding, Error> {
        // the instance's chain in its own namespace, then the outer levels with the instance's
        // path mapped into each
        let here = instance.path();
        let mut levels = Vec::new();
        for p in here.ancestors_below_root() {
            if outer.prototype.as_ref() == Some(&p) {
                break;
            }
            levels.push((p, here.clone()));
        }
        for (p, root) in &outer.levels {
            let mapped = match &outer.prototype {
                Some(proto) => here.replace_prefix(proto, root).unwrap_or_else(|| root.clone()),
                None => here.clone(),
            };
            levels.push((p.clone(), mapped));
        }
        let key = self.key(instance.stage(), &levels, warnings)?;
        Ok(InheritedBinding { levels, prototype: Some(prototype.clone()), key })
    }

    /// The cache key of an instance chain: [`BindingKey::Uniform`] unless a collection on it
    /// has an opinion on a path inside the instance, else [`BindingKey::Relative`].
    fn key(
        &mut self,
        stage: &usd::Stage,
        levels: &[(sdf::Path, sdf::Path)],
        warnings: &mut Vec<String>,
    ) -> Result<BindingKey, Error> {
        // each level's bindings, as seen from inside the instance
        let mut read = Vec::new();
        let mut relative = String::new();
        let mut uniform = true;
        for (p, root) in levels {
            let b = self.read(&stage.prim(p.clone()), warnings)?;
            if b.direct.is_some() || !b.full.is_empty() || !b.all.is_empty() {
                relative.push('#');
            }
            if let Some(d) = &b.direct {
                relative += &format!("|{}:{:?}:{}", d.material, d.purpose, d.stronger);
            }
            for (purpose, c) in b.full.iter().map(|c| (Purpose::Full, c)).chain(b.all.iter().map(|c| (Purpose::All, c)))
            {
                let inside = inside_opinions(&c.query, root);
                uniform &= inside.is_empty();
                relative += &format!(
                    "|{}:{purpose:?}:{}:{}:{inside:?}",
                    c.material,
                    c.stronger,
                    descendants_included(&c.query, root)
                );
            }
            read.push((b, root));
        }
        if !uniform {
            return Ok(BindingKey::Relative(relative));
        }
        // per pass, the outcome with nothing nearer and over a nearer binding
        let mut out: [Option<sdf::Path>; 4] = Default::default();
        for (k, purpose) in [Purpose::Full, Purpose::All].into_iter().enumerate() {
            for (slot, taken) in [(0, false), (1, true)] {
                let mut walk = Walk { taken, ..Walk::default() };
                for (j, (b, root)) in read.iter().enumerate() {
                    walk.step(j, b, purpose, &|q| descendants_included(q, root));
                }
                out[2 * k + slot] = walk.material;
            }
        }
        Ok(BindingKey::Uniform(out))
    }

    /// `prim`'s bindings for purpose `full`, read once.
    fn read(&mut self, prim: &usd::Prim, warnings: &mut Vec<String>) -> Result<Rc<PrimBindings>, Error> {
        if let Some(b) = self.by_prim.get(prim.path()) {
            return Ok(b.clone());
        }
        let b = Rc::new(read_bindings(prim, warnings)?);
        self.by_prim.insert(prim.path().clone(), b.clone());
        Ok(b)
    }
}

/// Whether the collection includes the prim `path`, as pxr's `IsPathIncluded` decides: the
/// nearest opinion on the prim or an ancestor, where an ancestor's `explicitOnly` opinion is
/// passed over (openusd's `MembershipQuery::is_path_included` stops at it).
fn includes(query: &MembershipQuery, path: &sdf::Path) -> bool {
    included_from(query, path, true)
}

/// Whether the prims below `root` that the collection has no opinion on are members.
fn descendants_included(query: &MembershipQuery, root: &sdf::Path) -> bool {
    included_from(query, root, false)
}

/// pxr's walk from `start` up: `Exclude` excludes, `explicitOnly` includes only the prim
/// asked about (`start`, when `start_is_prim`), any other rule includes.
fn included_from(query: &MembershipQuery, start: &sdf::Path, start_is_prim: bool) -> bool {
    for p in start.ancestors() {
        match query.rule_map().get(&p) {
            Some(PathRule::Exclude) => return false,
            Some(PathRule::ExplicitOnly) if !(start_is_prim && &p == start) => {}
            Some(_) => return true,
            None => {}
        }
    }
    false
}

/// The collection's opinions on paths strictly below `root`, relative to it, sorted.
fn inside_opinions(query: &MembershipQuery, root: &sdf::Path) -> Vec<(String, String)> {
    let prefix = format!("{root}");
    let mut out: Vec<(String, String)> = query
        .rule_map()
        .iter()
        .filter(|(k, _)| k.has_prefix(root) && *k != root)
        .map(|(k, r)| (k.as_str()[prefix.len()..].to_string(), format!("{r:?}")))
        .collect();
    out.sort();
    out
}

/// The bindings on `prim` (pxr's `BindingsAtPrim` for purpose `full`).
fn read_bindings(prim: &usd::Prim, warnings: &mut Vec<String>) -> Result<PrimBindings, Error> {
    // the binding relationships authored, in dictionary order
    let mut names: Vec<String> = prim
        .property_names()
        .map_err(|e| Error::Prim {
            layer: layer_of_prim(prim),
            prim: prim.path().to_string(),
            message: format!("properties cannot be composed: {e:#}"),
        })?
        .iter()
        .map(|n| n.as_str().to_string())
        .filter(|n| n.starts_with("material:binding"))
        .collect();
    let mut out = PrimBindings::default();
    if names.is_empty() {
        return Ok(out);
    }
    names.sort_by(|a, b| dictionary_cmp(a, b));
    // the direct binding: `full` with one prim target, else all-purpose
    for (rel, purpose) in DIRECT {
        if !names.iter().any(|n| n == rel) {
            continue;
        }
        let targets = targets(prim, rel)?;
        match targets.as_slice() {
            [t] if !t.is_property_path() => {
                let stronger = stronger_than_descendants(prim, rel);
                out.direct = Some(Direct { material: t.clone(), purpose, stronger });
                break;
            }
            [] => {}
            _ => warnings.push(format!(
                "{}.{rel}: a direct binding needs one Material target, not {:?}; ignored (as pxr does)",
                prim.path(),
                targets.iter().map(|t| t.to_string()).collect::<Vec<_>>()
            )),
        }
    }
    // the collection bindings of each purpose
    for name in &names {
        let purpose = if name.starts_with(COLLECTION_FULL) {
            Purpose::Full
        } else if name.strip_prefix(COLLECTION_ALL).is_some_and(|rest| !rest.contains(':')) {
            Purpose::All
        } else {
            continue;
        };
        if let Some(c) = collection_binding(prim, name, warnings)? {
            match purpose {
                Purpose::Full => out.full.push(c),
                Purpose::All => out.all.push(c),
            }
        }
    }
    Ok(out)
}

/// The collection binding `rel` on `prim`, or None (warned) when it is malformed.
fn collection_binding(
    prim: &usd::Prim,
    rel: &str,
    warnings: &mut Vec<String>,
) -> Result<Option<CollectionBinding>, Error> {
    let targets = targets(prim, rel)?;
    let here = format!("{}.{rel}", prim.path());
    // one collection (a property path) and one material (a prim path), in either order
    let (collection, material) = match targets.as_slice() {
        [a, b] if a.is_property_path() != b.is_property_path() => {
            if a.is_property_path() {
                (a, b)
            } else {
                (b, a)
            }
        }
        [] => return Ok(None),
        _ => {
            warnings.push(format!(
                "{here}: a collection binding needs a collection and a Material target, not {:?}; ignored (as pxr does)",
                targets.iter().map(|t| t.to_string()).collect::<Vec<_>>()
            ));
            return Ok(None);
        }
    };
    // the collection: an applied CollectionAPI instance
    let applied = is_collection_api_path(collection).filter(|(owner, name)| {
        let owner = prim.stage().prim(owner.clone());
        owner.is_valid().unwrap_or(false) && owner.has_api_schema(format!("CollectionAPI:{name}")).unwrap_or(false)
    });
    let Some((owner, name)) = applied else {
        warnings.push(format!(
            "{here}: {collection} is not a collection (a prim's applied CollectionAPI); the binding is ignored (as pxr does)"
        ));
        return Ok(None);
    };
    let coll = Collection::new(owner, name);
    let stage = prim.stage();
    if coll.has_expression(stage).unwrap_or(false) {
        warnings.push(format!(
            "{here}: {collection} is a membershipExpression collection, which is not evaluated; the binding is ignored"
        ));
        return Ok(None);
    }
    let query = coll
        .compute_membership_query(stage)
        .map_err(|e| attr_error(prim, rel, format!("the membership of {collection} cannot be composed: {e:#}")))?;
    Ok(Some(CollectionBinding { query, material: material.clone(), stronger: stronger_than_descendants(prim, rel) }))
}

/// The forwarded targets of relationship `rel` on `prim` (as pxr's bindings read them).
fn targets(prim: &usd::Prim, rel: &str) -> Result<Vec<sdf::Path>, Error> {
    prim.relationship(rel)
        .forwarded_targets()
        .map_err(|e| attr_error(prim, rel, format!("the relationship's targets cannot be composed: {e:#}")))
}

/// Whether the binding relationship `rel` on `prim` is authored `strongerThanDescendants`.
fn stronger_than_descendants(prim: &usd::Prim, rel: &str) -> bool {
    // the usda reader holds the token as a string
    match prim.attribute(rel).get_metadata::<sdf::Value>("bindMaterialAs") {
        Ok(Some(sdf::Value::Token(t))) => t.as_str() == "strongerThanDescendants",
        Ok(Some(sdf::Value::String(s))) => s == "strongerThanDescendants",
        _ => false,
    }
}

/// pxr's `TfDictionaryLessThan` as an ordering: letters compare case-insensitively (then
/// upper case first), runs of digits by value (then fewer leading zeros first), other
/// characters by their code.
pub fn dictionary_cmp(a: &str, b: &str) -> Ordering {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    let mut zeros = Ordering::Equal;
    let mut case = Ordering::Equal;
    while i < a.len() && j < b.len() {
        if a[i].is_ascii_digit() && b[j].is_ascii_digit() {
            // digit runs as numbers
            let (si, sj) = (i, j);
            while i < a.len() && a[i].is_ascii_digit() {
                i += 1;
            }
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            let (da, db) = (&a[si..i], &b[sj..j]);
            let (ta, tb) = (trim_zeros(da), trim_zeros(db));
            let by_value = ta.len().cmp(&tb.len()).then_with(|| ta.cmp(tb));
            if by_value != Ordering::Equal {
                return by_value;
            }
            if zeros == Ordering::Equal {
                zeros = da.len().cmp(&db.len());
            }
            continue;
        }
        let (ca, cb) = (a[i].to_ascii_lowercase(), b[j].to_ascii_lowercase());
        if ca != cb {
            return ca.cmp(&cb);
        }
        if case == Ordering::Equal {
            case = a[i].cmp(&b[j]);
        }
        i += 1;
        j += 1;
    }
    (a.len() - i).cmp(&(b.len() - j)).then(zeros).then(case)
}

/// `digits` without its leading zeros.
fn trim_zeros(digits: &[u8]) -> &[u8] {
    let k = digits.iter().position(|&c| c != b'0').unwrap_or(digits.len());
    &digits[k..]
}

#[cfg(test)]
mod tests {
    use super::dictionary_cmp;

    /// The order pxr's `GetAuthoredPropertyNames` (TfDictionaryLessThan) gave usd-core 26.11
    /// for these names, authored shuffled.
    #[test]
    fn dictionary_order_is_pxrs() {
        let want = [
            "_a", "A", "a", "a0b", "a1", "a9c", "a10b", "a:b", "a_", "a_b", "AB", "Ab", "aB", "ab", "Ab1", "ab2", "aZ",
            "B", "b1", "b_1", "c", "x9", "x09", "x009", "x10", "z",
        ];
        let mut got = want.to_vec();
        got.reverse();
        got.sort_by(|a, b| dictionary_cmp(a, b));
        assert_eq!(got, want);
        for w in want.windows(2) {
            assert_eq!(dictionary_cmp(w[0], w[1]), std::cmp::Ordering::Less, "{} < {}", w[0], w[1]);
        }
    }
}
