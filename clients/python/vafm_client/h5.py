# SPDX-License-Identifier: MIT
"""Loader of HDF5 force-curve files in afmformats' layout (protocol/hdf5.md), with h5py.

    from vafm_client import load_h5
    f = load_h5("curves.h5")
    for c in f.curves:                  # Curve: channels as numpy arrays, metadata, ground truth
        F, z = c["force"], c["height (piezo)"]
        print(c.group, c.meta["spring constant"], c.truth and c.truth["pulloff_spring_N"])
    print(f.is_vafm, f.scene["k_N_per_m"], f.seed, f.grid)
    if f.is_map:                        # a force map (vafm map, or any file with afmformats' map attributes)
        E = f.map_array([c.truth["E_star_Pa"] for c in f])   # [iy, ix]; NaN where no curve
        print(f.map_shape, f.map_extent, f.map_spec)         # (nx, ny), (x0, x1, y0, y1) m, vafm's spec or None

Any file of the layout loads (vafm's, afmformats' exports, instrument conversions: `time` and
`tip position` may be absent); vafm's provenance (scene, grid, seed, ground truth) is read when present.
A file that breaks the layout's structure (root objects that are not curve groups named 0..n-1, a curve
without force/heights/segment, channels of different lengths, an imaging mode other than
force-distance) raises ValueError naming the file, the object and the rule (protocol/hdf5.md L4-L10).
So does a dataset whose data lie outside the file (external raw-data storage, a virtual dataset: L2), which
is never read, and a channel longer than a vafm curve may be (VAFM_H5_MAX_SAMPLES), before it is read. The
map's pixel indices, its shape (at most VAFM_MAP_MAX_SIDE a side) and the ground-truth tables are checked
as they are used: a hostile file raises ValueError naming it, it is not misread.
"""
import json

import numpy as np

CHANNELS = ("force", "height (measured)", "height (piezo)", "segment", "time", "tip position")
REQUIRED = ("force", "height (measured)", "height (piezo)", "segment")
TRUTH = "vafm ground truth"
TRUTH_PART = TRUTH + " from "  # + the part's first curve: the rows of one flush (a killed writer's file)
MAP_MAX_SIDE = 1024  # VAFM_MAP_MAX_SIDE (include/vafm/map.h): pixels a side of a map
MAX_SAMPLES = 1 << 25  # VAFM_H5_MAX_SAMPLES (src/h5/h5.h): samples of one curve


def _str(v):
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray) and v.shape == ():
        return _str(v[()])
    if isinstance(v, np.generic):
        return v.item()
    return v


class Curve:
    """One curve group: `channels` {name: numpy array} (the datasets present, SI; force positive
    repulsive, heights decreasing toward the sample), `meta` {attribute: value} (afmformats' names:
    "spring constant", "rate approach", ...), `units` {name: unit}, `group` (its number), `truth`
    (vafm's ground-truth row as a dict, or None) and `segments`, the segment list the curve ran (one dict a
    segment: the file's one list, format 1.2, or the curve's own, format 1.3) or None (a force-distance curve)."""

    def __init__(self, group, channels, units, meta, truth=None, segments=None):
        self.group, self.channels, self.units, self.meta, self.truth = group, channels, units, meta, truth
        self.segments = segments

    def __getitem__(self, name):
        return self.channels[name]

    def __contains__(self, name):
        return name in self.channels

    def __len__(self):
        return len(self.channels["force"])

    @property
    def force(self):
        return self.channels["force"]

    @property
    def height(self):
        return self.channels["height (piezo)"]

    @property
    def segment(self):
        return self.channels["segment"]

    @property
    def time(self):
        """Seconds from the start of the curve, or None (optional in the layout)."""
        return self.channels.get("time")

    @property
    def approach(self):
        """Boolean mask of the approach samples (segment 0)."""
        return self.segment == 0

    @property
    def retract(self):
        """Boolean mask of the retract samples (segment 1)."""
        return self.segment == 1

    def __repr__(self):
        return f"<Curve {self.group}: {len(self)} samples, channels {sorted(self.channels)}>"


class H5File:
    """A loaded file: `curves` (list of Curve, in group order), `software`, `software_version`, `attrs`
    (every root attribute), and for vafm files (`is_vafm`) `format_version`, `scene` (dict), `grid`
    (dict), `seed`, `created` and `truth` (the ground-truth table as a numpy structured array, one row per
    curve, or None; format 1.1 rows carry each curve's E_star_Pa, gamma_J_per_m2, surface_height_m). A force
    map (`is_map`) has `map_shape`, `map_extent`, `map_spec` and `map_array(values)`. A file whose curves run a
    segment list (format 1.2, "vafm segments") has `segments`, the list (one dict a segment; None otherwise):
    its curves' `segment` is the segment's position, so `approach`/`retract` are then segments 0 and 1. In a
    format 1.3 file (a daemon's log) each curve may carry its own list ("vafm segments <group>"): see
    Curve.segments, which every file fills."""

    def __init__(self, path, curves, attrs, truth):
        self.path, self.curves, self.attrs, self.truth = path, curves, attrs, truth
        self.software = attrs.get("software")
        self.software_version = attrs.get("software version")
        self.format_version = attrs.get("vafm format version")
        self.is_vafm = self.format_version is not None
        self.scene = json.loads(attrs["vafm scene"]) if "vafm scene" in attrs else None
        self.grid = json.loads(attrs["vafm grid"]) if "vafm grid" in attrs else None
        self.seed = int(attrs["vafm seed"]) if "vafm seed" in attrs else None
        self.created = attrs.get("vafm created")
        self.segments = None
        if SEGMENTS in attrs:
            self.segments = _segment_list(path, SEGMENTS, attrs[SEGMENTS], "V6")

    @property
    def is_map(self):
        """True when the curves carry afmformats' map attributes ("grid shape x|y", "grid index x|y")."""
        return bool(self.curves) and all(k in self.curves[0].meta for k in
                                         ("grid shape x", "grid shape y", "grid index x", "grid index y"))

    def _grid_int(self, c, name, hi, limit):
        """Curve c's attribute `name` (afmformats' grid shape or index) as an int in [0, hi], else ValueError
        naming the file, the curve and the attribute, and for a value above hi the `limit`."""
        v = c.meta.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not float(v).is_integer() or v < 0:
            raise _bad(self.path, f"/{c.group}", "L17", f"'{name}' is {v!r} (afmformats wants a non-negative integer)")
        if v > hi:
            raise ValueError(f"{self.path}: /{c.group}: '{name}' is {int(v)}, above {hi} ({limit})")
        return int(v)

    @property
    def map_shape(self):
        """(nx, ny) of a map, from curve 0's "grid shape x|y": 1 to MAP_MAX_SIDE each (vafm's limit; a larger
        shape raises ValueError instead of allocating what the file claims)."""
        c = self.curves[0]
        nx, ny = (self._grid_int(c, f"grid shape {a}", MAP_MAX_SIDE, f"a map has at most {MAP_MAX_SIDE} pixels a "
                                 f"side, VAFM_MAP_MAX_SIDE") for a in "xy")
        if not nx or not ny:
            raise _bad(self.path, f"/{c.group}", "L17", "'grid shape x|y' is 0 (a map has at least one pixel)")
        return nx, ny

    @property
    def map_extent(self):
        """(x0, x1, y0, y1) of a map in m: "grid center" -+ "grid size"/2 (afmformats' convention: the size
        spans the whole image, the pixels' boundaries included); for matplotlib's imshow(extent=...)."""
        m = self.curves[0].meta
        cx, cy, sx, sy = (float(m[k]) for k in ("grid center x", "grid center y", "grid size x", "grid size y"))
        return cx - sx / 2, cx + sx / 2, cy - sy / 2, cy + sy / 2

    @property
    def map_spec(self):
        """vafm's map spec (the grid's "map": pattern, materials, ...; protocol/hdf5.md), or None."""
        return (self.grid or {}).get("map")

    def map_array(self, values):
        """Per-curve values (one per curve, in curve order) as a 2-D array [iy, ix] placed by each curve's
        "grid index x|y"; NaN where no curve sits. An index that is not a whole number inside the map's shape,
        or two curves on one pixel, raise ValueError (numpy would wrap a negative index, and the later curve
        would overwrite the other: a wrong map without a word)."""
        nx, ny = self.map_shape
        out = np.full((ny, nx), np.nan)
        owner = {}
        for c, v in zip(self.curves, values):
            ix, iy = (self._grid_int(c, f"grid index {a}", n - 1, f"outside 'grid shape {a}' {n}")
                      for a, n in (("x", nx), ("y", ny)))
            if (ix, iy) in owner:
                raise ValueError(f"{self.path}: /{c.group}: pixel ({ix}, {iy}) is curve {owner[ix, iy]}'s too "
                                 f"(one curve per pixel)")
            owner[ix, iy] = c.group
            out[iy, ix] = np.nan if v is None else v
        return out

    def __len__(self):
        return len(self.curves)

    def __getitem__(self, i):
        return self.curves[i]

    def __iter__(self):
        return iter(self.curves)

    def __repr__(self):
        return f"<H5File {self.path}: {len(self.curves)} curve(s), software {self.software}>"


def _bad(path, obj, rule, what):
    return ValueError(f"[{rule}] {path}: {obj}: {what}")


def _truth_table(path, root):
    """The merged table plus any per-flush parts a killed writer left ("vafm ground truth from <i>"), sorted
    by curve; ValueError naming the file and the attribute for what is not such a table (V4)."""
    parts = []
    for name in root.attrs:
        if name != TRUTH and not name.startswith(TRUTH_PART):
            continue
        first = name[len(TRUTH_PART):] if name != TRUTH else "-1"
        if name != TRUTH and not (first.isascii() and first.isdigit()):
            raise _bad(path, "/", "V4", f"attribute '{name}': a part of the ground truth is named "
                                        f"'{TRUTH_PART}<first curve>', a decimal number")
        p = np.asarray(root.attrs[name])
        if p.dtype.names is None or p.ndim != 1:
            raise _bad(path, "/", "V4", f"attribute '{name}' is not a 1-D compound table (the ground truth)")
        if "curve" not in p.dtype.names or p.dtype["curve"].kind not in "iu":
            raise _bad(path, "/", "V4", f"attribute '{name}' lacks the integer field 'curve'")
        parts.append((int(first), name, p))
    if not parts:
        return None
    parts.sort(key=lambda x: x[0])
    try:
        t = np.concatenate([p for _, _, p in parts])
    except (TypeError, ValueError) as e:  # numpy: the parts' fields differ
        raise _bad(path, "/", "V4", f"the ground-truth attributes {[n for _, n, _ in parts]} are tables of "
                                    f"different fields ({e})") from None
    t = t[np.argsort(t["curve"], kind="stable")]
    dup = np.flatnonzero(t["curve"][1:] == t["curve"][:-1])
    if dup.size:
        raise _bad(path, "/", "V4", f"two ground-truth rows for curve {int(t['curve'][dup[0]])} (one row per curve)")
    return t


SEGMENTS = "vafm segments"  # format 1.2: the list of every curve; + " <group>" (format 1.3): one curve's own


def _segment_list(path, name, text, rule):
    """The segments of root attribute `name` ({"segments": [1 to 255 objects]}), else ValueError naming it."""
    try:
        seg = json.loads(text)
    except (TypeError, ValueError):
        seg = None
    if not (isinstance(seg, dict) and list(seg) == ["segments"] and isinstance(seg["segments"], list)
            and 1 <= len(seg["segments"]) <= 255 and all(isinstance(s, dict) for s in seg["segments"])):
        raise _bad(path, "/", rule, f"'{name}' is not a segment list {{\"segments\": [1 to 255 objects]}}")
    return seg["segments"]


def load_h5(path, channels=True):
    """Load every curve of `path` (channels=False: metadata and ground truth only, no arrays read)."""
    import h5py  # Debian: python3-h5py; imported here so that the stream client does not need it
    with h5py.File(path, "r") as root:
        attrs = {k: _str(v) for k, v in root.attrs.items() if not k.startswith(TRUTH)}
        for k in ("software", "software version"):
            if k not in attrs:
                raise _bad(path, "/", "L3", f"root attribute '{k}' missing")
        names = list(root.keys())
        for n in names:
            if not (n.isdigit() and (n == "0" or not n.startswith("0"))) or not isinstance(root[n], h5py.Group):
                raise _bad(path, f"/{n}", "L4", "the root holds only curve groups named 0, 1, 2, ...")
        groups = sorted(int(n) for n in names)
        if groups != list(range(len(groups))):
            raise _bad(path, "/", "L4", "curve groups are not numbered 0..n-1 without gaps")
        truth = _truth_table(path, root)
        rows = {int(r["curve"]): r for r in truth} if truth is not None else {}
        curves = []
        for g in groups:
            grp = root[str(g)]
            for n in grp:
                if n not in CHANNELS:
                    raise _bad(path, f"/{g}/{n}", "L5", "not a dataset name of the layout")
                d = grp[n]
                if not isinstance(d, h5py.Dataset):
                    raise _bad(path, f"/{g}/{n}", "L5", "not a dataset (a curve group holds no subgroups)")
                # before its shape or data: HDF5 opens such a dataset's other files on a read, and they can
                # name any path (a FIFO blocks the reader for ever)
                if d.is_virtual:
                    raise _bad(path, f"/{g}/{n}", "L2", "a virtual dataset, its data in other files (not read)")
                if d.external:
                    raise _bad(path, f"/{g}/{n}", "L2", "stored in an external file (not read)")
            for n in REQUIRED:
                if n not in grp:
                    raise _bad(path, f"/{g}", "L6", f"dataset '{n}' missing")
            meta = {k: _str(v) for k, v in grp.attrs.items()}
            if meta.get("imaging mode") != "force-distance":
                raise _bad(path, f"/{g}", "L10", f"imaging mode is {meta.get('imaging mode')!r}, not force-distance")
            units = {n: _str(grp[n].attrs.get("unit")) for n in grp}
            lengths = {n: grp[n].shape for n in grp}
            if len(set(lengths.values())) != 1 or len(next(iter(lengths.values()))) != 1:
                raise _bad(path, f"/{g}", "L7", f"datasets are not 1-D of one length: {lengths}")
            if next(iter(lengths.values()))[0] > MAX_SAMPLES:  # a small file can declare terabytes
                raise _bad(path, f"/{g}", "L7", f"datasets declare {next(iter(lengths.values()))[0]} samples, more "
                                                f"than a curve may have ({MAX_SAMPLES}, VAFM_H5_MAX_SAMPLES): not read")
            chans = {n: grp[n][()] for n in grp} if channels else {}
            row = rows.get(g)
            t = {k: _str(row[k]) for k in row.dtype.names} if row is not None else None
            own = f"{SEGMENTS} {g}"  # format 1.3: the curve's own list (hdf5.md V7)
            segs = _segment_list(path, own, attrs[own], "V7") if own in attrs else None
            if segs is None and SEGMENTS in attrs:
                segs = _segment_list(path, SEGMENTS, attrs[SEGMENTS], "V6")
            curves.append(Curve(g, chans, units, meta, t, segs))
    return H5File(path, curves, attrs, truth)
