"""Checks an imubake `convert --report` HTML document and describes what it shows, as JSON.

Usage: check_report.py REPORT.html [SPEC_JSON]

The document is parsed with `html.parser` and must be well formed: every element closed in
order (HTML void elements aside), nothing left open, one <!DOCTYPE html>. Every <svg> is cut out
of the source text and parsed with `xml.etree.ElementTree` (which fails on anything that is not
well-formed XML). A failure exits with status 1 and a message on stderr.

Printed on stdout (one JSON object):
- `title`, `doctype`, `start_tags` (count per tag name, e.g. to see that there is no `script`),
  `external` (attribute values pointing to http(s) resources other than the SVG namespace),
- `header` (the summary's terms → values), `warnings` (text of each item), `dropped` (texts of
  `.dropped`), `sensor_rows` (cell texts of each body row of the sensor table),
- `charts`: per `figure.bone`, `bone` and `order` (its data attributes), `svg_count`,
  `texts` (the SVG's <text> contents), `curves` and `legend_lines`. A curve is a coloured
  (non-black) <polyline> inside the plot area (`data-plot-px`); others to the right of it are
  legend samples. Per curve: `stroke`, `width`, `opacity`, `points`, and the points mapped back to
  data units through `data-plot-px` / `data-plot-range` (the SVG coordinates of the plot's
  corners and the data values there; a pixel is read as its centre): `t_min`, `t_max`, `v_min`,
  `v_max`.

SPEC_JSON, optional: `{"sine": {"bone": NAME, "amp": A, "freq": F, "phase": P, "offset": O}}`:
for every curve of that bone's chart, `sine_corr` is the correlation between the curve's values
(mapped from the SVG y coordinates) and `O + A sin(2 pi F t + P)` at the curve's own times
(mapped from the SVG x coordinates), and `sine_rms` the RMS difference in degrees.
"""

import json
import math
import sys
import xml.etree.ElementTree as ET
from html.parser import HTMLParser

VOID = {
    "area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source",
    "track", "wbr",
}
# Elements whose text is collected (none of them nests another).
TEXT_TAGS = {"title", "dt", "dd", "li", "td", "span"}
SVG_NS = "{http://www.w3.org/2000/svg}"


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


class Report(HTMLParser):
    def __init__(self, source):
        super().__init__(convert_charrefs=True)
        self.source = source
        # Offsets of line starts, to turn getpos() into an offset in `source`.
        self.line_starts = [0]
        for i, c in enumerate(source):
            if c == "\n":
                self.line_starts.append(i + 1)
        self.stack = []  # (tag, attrs)
        self.start_tags = {}
        self.external = []
        self.doctype = []
        self.title = ""
        self.header = {}
        self.warnings = []
        self.dropped = []
        self.sensor_rows = []
        self.charts = []
        self.svg_start = None
        self.text = None  # collecting text for the innermost element of interest
        self.last_dt = None

    def source_offset(self):
        line, col = self.getpos()
        return self.line_starts[line - 1] + col

    def inside(self, tag, cls=None):
        for (t, a) in self.stack:
            if t == tag and (cls is None or cls in (dict(a).get("class") or "").split()):
                return True
        return False

    def handle_decl(self, decl):
        self.doctype.append(decl)

    def handle_starttag(self, tag, attrs):
        self.start_tags[tag] = self.start_tags.get(tag, 0) + 1
        for name, value in attrs:
            if value and value.startswith(("http://", "https://", "//")):
                if not (name == "xmlns" and value == "http://www.w3.org/2000/svg"):
                    self.external.append(f"{tag} {name}={value}")
        a = dict(attrs)
        if tag == "figure" and "bone" in (a.get("class") or "").split():
            self.charts.append({
                "bone": a.get("data-bone"),
                "order": a.get("data-order"),
                "plot_px": [float(v) for v in (a.get("data-plot-px") or "").split()],
                "plot_range": [float(v) for v in (a.get("data-plot-range") or "").split()],
                "svg_count": 0,
                "svgs": [],
            })
        if tag == "svg":
            if self.svg_start is not None:
                fail("nested <svg>")
            self.svg_start = self.source_offset()
        if tag == "tr" and self.inside("table", "sensors") and self.inside("tbody"):
            self.sensor_rows.append([])
        if tag in VOID:
            return
        self.stack.append((tag, attrs))
        if tag in TEXT_TAGS:
            self.text = []

    def handle_startendtag(self, tag, attrs):
        # `<x/>`: inside SVG a complete element; in HTML only void elements may be written so.
        if self.svg_start is None and tag not in VOID:
            fail(f"self-closing non-void <{tag}/> outside SVG at {self.getpos()}")
        self.start_tags[tag] = self.start_tags.get(tag, 0) + 1

    def handle_endtag(self, tag):
        if tag in VOID:
            fail(f"end tag for void element </{tag}> at {self.getpos()}")
        if not self.stack or self.stack[-1][0] != tag:
            open_tags = [t for t, _ in self.stack]
            fail(f"</{tag}> at {self.getpos()} does not close the innermost open element: {open_tags}")
        text = "".join(self.text).strip() if self.text is not None else None
        if tag in TEXT_TAGS:
            self.text = None
        if tag == "title":
            self.title = text
        elif tag == "dt" and self.inside("dl", "summary"):
            self.last_dt = text
        elif tag == "dd" and self.inside("dl", "summary"):
            self.header[self.last_dt] = text
        elif tag == "li" and self.inside("ul", "warnings"):
            self.warnings.append(text)
        elif tag == "td" and self.sensor_rows and self.inside("table", "sensors"):
            self.sensor_rows[-1].append(text)
        elif tag == "span" and "dropped" in (dict(self.stack[-1][1]).get("class") or "").split():
            self.dropped.append(text)
        if tag == "dd" and "dropped" in (dict(self.stack[-1][1]).get("class") or "").split():
            self.dropped.append(text)
        if tag == "svg":
            start = self.svg_start
            end = self.source.index(">", self.source_offset()) + 1
            self.svg_start = None
            if not self.charts or not self.inside("figure", "bone"):
                fail("an <svg> outside a bone figure")
            self.charts[-1]["svg_count"] += 1
            self.charts[-1]["svgs"].append(self.source[start:end])
        self.stack.pop()

    def handle_data(self, data):
        if self.text is not None:
            self.text.append(data)


def points_of(poly):
    pts = []
    for pair in poly.get("points", "").split():
        x, y = pair.split(",")
        pts.append((float(x), float(y)))
    return pts


def correlation(a, b):
    n = len(a)
    ma, mb = sum(a) / n, sum(b) / n
    va = sum((x - ma) ** 2 for x in a)
    vb = sum((y - mb) ** 2 for y in b)
    if va == 0 or vb == 0:
        return 0.0
    return sum((x - ma) * (y - mb) for x, y in zip(a, b)) / math.sqrt(va * vb)


def describe_chart(chart, spec):
    svgs = chart.pop("svgs")
    if len(svgs) != 1:
        return
    try:
        root = ET.fromstring(svgs[0])
    except ET.ParseError as e:
        fail(f"the SVG of {chart['bone']!r} is not well-formed XML: {e}")
    if root.tag != SVG_NS + "svg":
        fail(f"the SVG root of {chart['bone']!r} is {root.tag}")
    x0, y0, x1, y1 = chart["plot_px"]
    t0, v0, t1, v1 = chart["plot_range"]

    # plotters maps a value to the pixel whose start it passes (floor in the direction of the
    # axis), so a drawn pixel stands for the half-pixel after it along that axis.
    sx = math.copysign(0.5, x1 - x0)
    sy = math.copysign(0.5, y1 - y0)

    def to_data(x, y):
        return (
            t0 + (x + sx - x0) / (x1 - x0) * (t1 - t0),
            v0 + (y + sy - y0) / (y1 - y0) * (v1 - v0),
        )

    chart["texts"] = [(t.text or "").strip() for t in root.iter(SVG_NS + "text")]
    chart["curves"] = []
    chart["legend_lines"] = []
    sine = spec.get("sine")
    for poly in root.iter(SVG_NS + "polyline"):
        stroke = poly.get("stroke", "").upper()
        if stroke == "#000000":
            continue
        pts = points_of(poly)
        entry = {
            "stroke": stroke,
            "width": float(poly.get("stroke-width", "1")),
            "opacity": float(poly.get("opacity", "1")),
            "points": len(pts),
        }
        if pts and all(x0 <= x <= x1 for x, _ in pts):
            data = [to_data(x, y) for x, y in pts]
            ts = [t for t, _ in data]
            vs = [v for _, v in data]
            entry.update(t_min=min(ts), t_max=max(ts), v_min=min(vs), v_max=max(vs))
            if sine and sine["bone"] == chart["bone"] and len(pts) > 2:
                expected = [
                    sine["offset"] + sine["amp"] * math.sin(2 * math.pi * sine["freq"] * t + sine["phase"])
                    for t in ts
                ]
                entry["sine_corr"] = correlation(vs, expected)
                entry["sine_rms"] = math.sqrt(sum((v - e) ** 2 for v, e in zip(vs, expected)) / len(vs))
            chart["curves"].append(entry)
        else:
            chart["legend_lines"].append(entry)


def main():
    if len(sys.argv) not in (2, 3):
        fail(__doc__)
    with open(sys.argv[1], encoding="utf-8") as f:
        source = f.read()
    spec = json.loads(sys.argv[2]) if len(sys.argv) == 3 else {}
    parser = Report(source)
    parser.feed(source)
    parser.close()
    if parser.stack:
        fail(f"elements left open: {[t for t, _ in parser.stack]}")
    if parser.svg_start is not None:
        fail("an <svg> left open")
    for chart in parser.charts:
        describe_chart(chart, spec)
    print(json.dumps({
        "title": parser.title,
        "doctype": parser.doctype,
        "start_tags": parser.start_tags,
        "external": parser.external,
        "header": parser.header,
        "warnings": parser.warnings,
        "dropped": parser.dropped,
        "sensor_rows": parser.sensor_rows,
        "charts": parser.charts,
    }))


if __name__ == "__main__":
    main()
