"""Charging pads from a file: CSV with a header (``lat``, ``lon``, optional ``alt`` in m AMSL and
``hover_time_s``; also ``latitude``/``longitude``/``lng``/``altitude``/``alt_amsl``, :data:`_ALIASES`) or GeoJSON (Point /
MultiPoint geometries, coordinates [lon, lat(, alt)], optional property ``hover_time_s``).

Returns :class:`GeoPad` records; :mod:`.route` puts them into the pad frame. Errors are one line
naming the file and the row / feature.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass

from ..mavlink.geodesy import GeoPoint
from ..validation import HOLD_RANGE, check_range, clipped, json_too_deep, shown

__all__ = ["GeoPad", "read_pads", "check_distinct", "MAX_PADS", "SAME_PAD_M"]

MAX_PADS = 100
_ALIASES = {"lat": ("lat", "lat_deg", "latitude"), "lon": ("lon", "lon_deg", "lng", "long", "longitude"),
            "alt": ("alt", "alt_m", "altitude", "amsl_m", "alt_amsl"), "hover_time_s": ("hover_time_s", "hover_s")}


@dataclass(frozen=True)
class GeoPad:
    """A pad: its coil centre (altitude m AMSL, None = on the home's ground) and hover time (None = default)."""

    point: GeoPoint
    hover_time_s: float | None = None


def read_pads(path) -> tuple[GeoPad, ...]:
    """Pads of a CSV or GeoJSON file (by content: a JSON object, else CSV; a JSON array is refused)."""
    from ..validation import check_regular_file
    path = check_regular_file(path, "pads file (--pads / mission.pads_file)", "a CSV or GeoJSON file")
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path.name}: not a UTF-8 text file: byte {exc.object[exc.start]:#04x} at offset {exc.start}") from None
    if text.lstrip().startswith("["):
        _refuse_json_array(text, path.name)
    pads = _geojson(text, path.name) if text.lstrip().startswith("{") else _csv(text, path.name)
    if not 1 <= len(pads) <= MAX_PADS:
        raise ValueError(f"{path.name}: {len(pads)} pads; valid: 1..{MAX_PADS}")
    return pads


def _refuse_json_array(text: str, name: str) -> None:
    """A JSON array is no pads file: said so, with the two forms a pads file has (2026-11-28: it was read as a CSV,
    "header '[1,2,3]' has no lat / lon column"). Text starting with ``[`` that is not JSON is left to the CSV reader."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError:
        return
    except RecursionError:   # '[' * 100000: the parser's recursion, a traceback until 2026-11-28
        raise ValueError(_too_deep(name)) from None
    raise ValueError(f"{name}: a JSON array ({len(doc)} item{'s' * (len(doc) != 1)}), not a pads file; valid: a GeoJSON "
                     "object {\"type\": \"FeatureCollection\", \"features\": [...]} of Point / MultiPoint features "
                     "(coordinates [lon, lat] or [lon, lat, alt], property hover_time_s), or a CSV with a header "
                     "lat,lon[,alt][,hover_time_s]")


def _too_deep(name: str) -> str:
    """The error of a JSON text nested deeper than Python's parser takes (its recursion limit)."""
    return json_too_deep(name, "a pads file", "a GeoJSON FeatureCollection of Point / MultiPoint features, or a CSV "
                         "with a header lat,lon[,alt][,hover_time_s]")


#: two pads closer than this (horizontally) are one pad listed twice: a re-flight made a detour to each and charged
#: there twice (`replay --pads` with a row pasted twice: 120 s of charging and twice the flight time gained, no word)
SAME_PAD_M = 0.1


def check_distinct(pads, name: str) -> None:
    """``ValueError`` naming the first two pads (1-based, file order) closer than :data:`SAME_PAD_M`. For a
    re-flight's pads only (:func:`~mission_sim.plans.refly.refly_base`), where each pad is one detour and one charge;
    :func:`read_pads` does not check it: the built-in pattern of ``mission --pads`` visits the pads in file order, so
    A, B, A is a route there."""
    import numpy as np

    from ..mavlink.geodesy import geodetic_to_enu
    ref = GeoPoint(pads[0].point.lat_deg, pads[0].point.lon_deg, 0.0)
    e, n, _ = geodetic_to_enu(np.array([p.point.lat_deg for p in pads]), np.array([p.point.lon_deg for p in pads]),
                              np.zeros(len(pads)), ref)
    d = np.hypot(np.subtract.outer(e, e), np.subtract.outer(n, n))
    close = np.argwhere(np.triu(d < SAME_PAD_M, k=1))
    if len(close):
        i, j = (int(v) for v in close[0])
        raise ValueError(f"{name}: pads {i + 1} and {j + 1} are {d[i, j]:.2f} m apart: one pad listed twice (a "
                         f"re-flight would charge at it twice); valid: pads at least {SAME_PAD_M:g} m apart")


def _pad(lat, lon, alt, hover, where: str) -> GeoPad:
    try:
        vals = [None if v is None else float(v) for v in (lat, lon, alt, hover)]
    except (TypeError, ValueError):
        raise ValueError(f"{where}: lat={shown(lat)}, lon={shown(lon)}, alt={shown(alt)}, hover_time_s={shown(hover)}: not numbers; valid: a number each") from None
    # the config's range of a hover time (this said [0, inf) s; 1e308 then failed as pads.0.hover_time_s, no file named)
    if vals[3] is not None:
        check_range(f"{where}: hover_time_s", hover, HOLD_RANGE)
    try:
        return GeoPad(GeoPoint(vals[0], vals[1], vals[2]), vals[3])
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _csv(text: str, name: str) -> tuple[GeoPad, ...]:
    reader = csv.reader(io.StringIO(text))
    # (the file's line number of each row: the reader's count after it, less the row's own line breaks in quotes)
    try:
        rows = [(reader.line_num - sum(c.count("\n") for c in r), r) for r in reader]
    except csv.Error as exc:   # a field over csv.field_size_limit() (128 KiB): a traceback until 2026-11-28
        raise ValueError(f"{name}: not a readable CSV: {exc} at line {reader.line_num}; valid: a CSV header "
                         "lat,lon[,alt][,hover_time_s] and rows of numbers (or a GeoJSON FeatureCollection of "
                         "Points)") from None
    rows = [(n, r) for n, r in rows if any(c.strip() for c in r)]
    if not rows:
        raise ValueError(f"{name}: empty pads file; valid: a CSV header lat,lon[,alt][,hover_time_s] and rows")
    head = [c.strip().lower() for c in rows[0][1]]
    col = {k: next((head.index(a) for a in al if a in head), None) for k, al in _ALIASES.items()}
    if col["lat"] is None or col["lon"] is None:
        raise ValueError(f"{name}: header {shown(','.join(head))} has no lat / lon column; valid: a CSV header "
                         "lat,lon[,alt][,hover_time_s] (or a GeoJSON FeatureCollection of Points)")
    _check_other_columns(head, f"{name}: column")
    if col["alt"] is None:
        _check_altitude_like(head, f"{name}: column")
    out = []
    for i, r in rows[1:]:   # i: the line in the file (blank lines counted)
        if any(c.strip() for c in r[len(head):]):   # (a value past the header's columns was dropped without a word)
            raise ValueError(f"{name}: line {i} has {len(r)} values, the header {len(head)} ({','.join(head)}); "
                             "valid: one value per header column (a missing alt / hover_time_s column?)")

        def get(k):
            j = col[k]
            return r[j].strip() if j is not None and j < len(r) and r[j].strip() else None
        out.append(_pad(get("lat"), get("lon"), get("alt"), get("hover_time_s"), f"{name}: line {i}"))
    return tuple(out)


#: every name of a pad's value a CSV column may have (:data:`_ALIASES`)
_KNOWN = tuple(a for al in _ALIASES.values() for a in al)
_CSV_VALID = ("valid columns: " + "; ".join(f"{k} ({', '.join(al[1:])})" for k, al in _ALIASES.items())
              + " (alt in m AMSL); other columns are ignored")
_GEOJSON_VALID = ("valid properties: hover_time_s (a pad's position and altitude are its coordinates, [lon, lat] or "
                  "[lon, lat, alt] in m AMSL); other properties are ignored")


def _check_other_columns(head, what: str) -> None:
    """CSV columns other than a pad value's (:data:`_ALIASES`) are ignored (a pad's name, a note), except one whose
    name looks like a pad value's (``hover_time``, ``altitude_m``, ``alt_agl``): its values would be dropped without
    a word. ``what``: the error's start (the file and ``column``)."""
    for c in head:
        field = None if c in _KNOWN else _near_field(c, _KNOWN)
        if field:
            raise ValueError(f"{what} {shown(c)} is unknown (did you mean {field!r}?); {_CSV_VALID}")


#: first words of a name that holds a height under another name or unit (``alt_ft``, ``altitude (ft)``, ``height``,
#: ``elevation_m``, ``z``): with no ``alt`` column its values were dropped without a word, the pad on the home's ground
_ALT_WORDS = frozenset({"alt", "altitude", "height", "hgt", "elev", "elevation", "ele", "amsl", "agl", "z"})
#: what may follow such a first word in a height's name (a unit, a reference): ``height_note``, ``z_index``,
#: ``agl_note`` are ordinary columns (ignored, as any other), not heights
_ALT_UNIT_WORDS = frozenset({"", "ft", "feet", "foot", "m", "meter", "meters", "metre", "metres", "amsl", "msl", "agl"})


def _check_altitude_like(head, what: str) -> None:
    """A file without a pad altitude column (:data:`_ALIASES` ``alt``) whose other column looks like one
    (:data:`_ALT_WORDS` followed by nothing but :data:`_ALT_UNIT_WORDS`: ``alt_ft``, ``Alt (ft)``, ``height``,
    ``elevation_m``; 2026-11-28, they were ignored): ``ValueError`` naming it. ``what``: the error's start (the file
    and ``column``)."""
    import re
    for c in head:
        words = re.split(r"[^a-z0-9]+", c.strip().lower())
        if words and words[0] in _ALT_WORDS and all(w in _ALT_UNIT_WORDS for w in words[1:]):
            raise ValueError(f"{what} {shown(c)} looks like a pad altitude but is not read (the pads would be on the "
                             "home's ground); valid: a column alt in metres above mean sea level (feet x 0.3048; a "
                             "height above ground: add the ground's altitude AMSL), or no such column")


def _near_field(name: str, names=_KNOWN) -> str | None:
    """The pad value (a key of :data:`_ALIASES`) one of whose ``names`` ``name`` nearly matches (a misspelling), or
    None."""
    import difflib
    near = difflib.get_close_matches(name, names, n=1, cutoff=0.75)
    return next(k for k, al in _ALIASES.items() if near[0] in al) if near else None


#: the GeoJSON ``type`` of a pads file's top-level object (the geometries other than Point / MultiPoint are refused
#: by name further on)
_GEOJSON_TYPES = ("FeatureCollection", "Feature", "Point", "MultiPoint", "LineString", "MultiLineString", "Polygon",
                  "MultiPolygon", "GeometryCollection")


def _geojson(text: str, name: str) -> tuple[GeoPad, ...]:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{name}: malformed JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:   # '{"a":' * 100000: the parser's recursion, a traceback until 2026-11-28
        raise ValueError(_too_deep(name)) from None
    if doc.get("type") not in _GEOJSON_TYPES and "geometry" not in doc:   # (a QGC .plan given as the pads: "feature 0:
        # geometry type null is not supported"; a feature without its "type" but with a geometry is read, as before)
        plan = (" (a QGroundControl .plan: give it as mission / telemetry --plan, or mission.file)"
                if doc.get("fileType") == "Plan" else "")
        what = ("a JSON object without a GeoJSON \"type\"" if doc.get("type") is None
                else f"type {shown(doc['type'])} is not GeoJSON's" if isinstance(doc.get("type"), str)
                else f"\"type\" {_json_shown(doc['type'])} is not GeoJSON's")
        raise ValueError(f"{name}: {what}{plan}, not a pads file; valid: a GeoJSON "
                         "FeatureCollection of Point / MultiPoint features (or one Feature or geometry), or a CSV "
                         "lat,lon[,alt][,hover_time_s]")
    feats = doc.get("features") if doc.get("type") == "FeatureCollection" else [doc]
    if not isinstance(feats, list):
        raise ValueError(f"{name}: \"features\" is not a list")
    out = []
    for i, f in enumerate(feats):
        where = f"{name}: feature {i}"
        coords, props = _geojson_feature(f, where)
        _check_geojson_properties(props, any(len(c) == 2 for c in coords), f"{where}: property")
        for c in coords:
            out.append(_pad(c[1], c[0], c[2] if len(c) == 3 else None, props.get("hover_time_s"), where))
    return tuple(out)


def _geojson_feature(f, where: str) -> tuple[list, dict]:
    """(coordinates, a list of [lon, lat(, alt)] numbers; properties, a dict) of one feature (or a bare Point /
    MultiPoint geometry); ``ValueError`` (``where``: the file and feature) naming what was found instead: a feature
    without geometry, a geometry other than Point / MultiPoint, ``properties`` that are not an object (``null``: none;
    a list or a string was an AttributeError), coordinates that are not JSON numbers (``true`` was 1.0 deg, ``"8.5"``
    taken as 8.5), a MultiPoint without ``coordinates`` (no pad, without a word), a ``hover_time_s`` that is not a JSON
    number (``"5"`` was taken). Values are shown as the file spells them (:func:`_json_shown`: ``null``, ``true``)."""
    if not isinstance(f, dict):
        raise ValueError(f"{where} is {_json_shown(f)}, not a GeoJSON object; valid: a Feature with a Point or "
                         "MultiPoint geometry")
    feature = f.get("type") == "Feature" or "geometry" in f
    geom, props = f.get("geometry") if feature else f, f.get("properties")
    if not isinstance(geom, dict):
        raise ValueError(f"{where}: geometry {_json_shown(geom)} is not a geometry object (a feature without one has "
                         "no location); valid: Point, MultiPoint")
    kind = geom.get("type")
    if kind not in ("Point", "MultiPoint"):
        raise ValueError(f"{where}: geometry type {_json_shown(kind)} is not supported; valid: Point, MultiPoint")
    if props is not None and not isinstance(props, dict):
        kind = _JSON_TYPES.get(type(props), type(props).__name__)
        raise ValueError(f"{where}: properties {_json_shown(props)} ({kind}) are not an object; valid: a JSON object "
                         "{...} or null (hover_time_s in it)")
    coords = [geom.get("coordinates")] if kind == "Point" else geom.get("coordinates")
    if not isinstance(coords, list):
        raise ValueError(f"{where}: MultiPoint coordinates {_json_shown(coords)} are invalid; valid: a list of "
                         "[lon, lat] or [lon, lat, alt]")
    for c in coords:
        if not isinstance(c, list) or len(c) not in (2, 3) or not all(_json_number(v) for v in c):
            raise ValueError(f"{where}: coordinates {_json_shown(c)} are invalid; valid: [lon, lat] or [lon, lat, alt], "
                             "JSON numbers")
    hover = (props or {}).get("hover_time_s")
    if hover is not None and not _json_number(hover):
        raise ValueError(f"{where}: hover_time_s={_json_shown(hover)} is invalid; valid range: {HOLD_RANGE.text()}, a JSON number")
    return coords, props or {}


#: JSON's names of the types ``json.load`` returns (what a feature's properties are, as the file says it)
_JSON_TYPES = {dict: "object", list: "array", str: "string", int: "number", float: "number", bool: "boolean",
               type(None): "null"}


def _json_shown(v) -> str:
    """``v`` (read by ``json.load``) as the file spells it: ``null``, ``true``, ``"8.5"`` (Python's ``None``, ``True``,
    ``'8.5'`` are not in the file)."""
    return clipped(json.dumps(v), v)   # (a 2,000-point coordinate array was a 34 kB line)


def _json_number(v) -> bool:
    """A JSON number (``true`` / ``false`` are Python ints, ``"8.5"`` a string: neither is)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_geojson_properties(props, flat: bool, what: str) -> None:
    """A GeoJSON feature reads only ``hover_time_s`` of its properties; the others are ignored (a name, an id, the
    ``lat`` / ``lon`` / ``altitude`` that CSV-to-GeoJSON exporters keep beside the coordinates), except those whose
    values would be lost without a word: a hover time under another name (``hover_s``, ``hover_time``,
    ``Hover_Time_S``: an alias or a near match) and an altitude (an alias of ``alt``, any case) when the feature's
    coordinates are 2-D (``flat``; the pad would be on the ground). ``what``: the error's start."""
    for c in props:
        if c == "hover_time_s" or not isinstance(c, str):
            continue
        if _near_field(c.lower(), _ALIASES["hover_time_s"]):
            raise ValueError(f"{what} {shown(c)} is unknown (did you mean 'hover_time_s'?); {_GEOJSON_VALID}")
        if flat and c.lower() in _ALIASES["alt"]:
            raise ValueError(f"{what} {shown(c)} is ignored (did you mean the coordinates' alt? the feature's coordinates are "
                             f"2-D, [lon, lat], the pad would be on the ground); {_GEOJSON_VALID}")
