"""Renders a Mitsuba XML scene with Mitsuba 3 (scalar_rgb) for pixguide's cross-check test
(renderer/tests/mitsuba_crosscheck.rs, docs/mitsuba-crosscheck.md).

    python render.py SCENE.xml OUT.bin WIDTH HEIGHT SPP_PER_SEED SEEDS MAX_DEPTH [OUT.exr]

The scene file is read as it is, except for the settings both renderers must share, which are
replaced in memory (the file is not changed):
- the sensor's film becomes an `hdrfilm` of WIDTH x HEIGHT with a box filter (each sample lands
  in exactly one pixel, as in pixguide), its sampler an `independent` one;
- every <integrator> is dropped and a `path` integrator with MAX_DEPTH and no Russian roulette
  (rr_depth > MAX_DEPTH; pixguide renders without it) renders the image;
- a conductor's `extEta` of 1 is dropped (Mitsuba 3 has no such parameter; 1 is its meaning);
- a bitmap's `filterType` `trilinear` or `ewa` (Mitsuba 0.6's mip-maps) becomes `bilinear`,
  the filter Mitsuba 3 and pixguide have;
- <shape type="obj"> elements whose mesh file does not exist are dropped, as pixguide's loader
  skips them (with a warning).
The image is rendered SEEDS times with SPP_PER_SEED samples and seeds 0..SEEDS-1; the per-pixel
mean of the seeds' images and the variance of that mean (from the spread of the seeds' means)
are written to OUT.bin: b"PGMI0001", u32 width, height, seeds, spp per seed, f64 render
seconds, then width*height*3 f32 means and as many f32 variances of the mean, row-major from the
top-left pixel, RGB. Mitsuba's `moment` integrator would give per-sample moments, but it
reports them in XYZ (no RGB cross terms), so independent seeds it is.
"""
import os
import struct
import sys
import time
import xml.etree.ElementTree as ET

import mitsuba as mi
import numpy as np


def prepared_xml(path, width, height, spp):
    tree = ET.parse(path)
    root = tree.getroot()
    base = os.path.dirname(os.path.abspath(path))
    for integ in root.findall("integrator"):
        root.remove(integ)
    for shape in root.findall("shape"):
        if shape.get("type") != "obj":
            continue
        for s in shape.findall("string"):
            if s.get("name") == "filename" and not os.path.isfile(os.path.join(base, s.get("value"))):
                root.remove(shape)
    # Mitsuba 0.6's conductors had an exterior IOR (`extEta`); Mitsuba 3's have none and refuse
    # the parameter. Bitterli's scenes set it to 1, which changes nothing: drop it there.
    for bsdf in root.iter("bsdf"):
        if bsdf.get("type") in ("conductor", "roughconductor"):
            for p in bsdf.findall("float"):
                if p.get("name") in ("extEta", "ext_eta"):
                    if float(p.get("value")) != 1.0:
                        raise SystemExit(f"{path}: Mitsuba 3 has no conductor extEta ({p.get('value')})")
                    bsdf.remove(p)
    # Mitsuba 0.6's mip-mapped bitmap filters (`trilinear`, `ewa`) are gone in Mitsuba 3, which
    # filters bilinearly (as pixguide does).
    for tex in root.iter("texture"):
        for p in tex.findall("string"):
            if p.get("name") in ("filterType", "filter_type") and p.get("value") in ("trilinear", "ewa"):
                p.set("value", "bilinear")
    sensors = root.findall("sensor")
    if len(sensors) != 1:
        raise SystemExit(f"{path}: expected one <sensor>, found {len(sensors)}")
    sensor = sensors[0]
    for c in list(sensor):
        if c.tag in ("film", "sampler"):
            sensor.remove(c)
    sampler = ET.SubElement(sensor, "sampler", type="independent")
    ET.SubElement(sampler, "integer", name="sample_count", value=str(spp))
    film = ET.SubElement(sensor, "film", type="hdrfilm")
    ET.SubElement(film, "integer", name="width", value=str(width))
    ET.SubElement(film, "integer", name="height", value=str(height))
    ET.SubElement(film, "rfilter", type="box")
    return ET.tostring(root, encoding="unicode"), base


def main():
    if len(sys.argv) not in (8, 9):
        raise SystemExit(__doc__)
    path, out = sys.argv[1], sys.argv[2]
    width, height, spp, seeds, max_depth = (int(a) for a in sys.argv[3:8])
    exr = sys.argv[8] if len(sys.argv) == 9 else None
    # Set here, not at import: bench.py imports prepared_xml and picks its own variant.
    mi.set_variant("scalar_rgb")
    text, base = prepared_xml(path, width, height, spp)
    mi.file_resolver().prepend(base)
    scene = mi.load_string(text)
    integrator = mi.load_dict({"type": "path", "max_depth": max_depth, "rr_depth": max_depth + 1, "hide_emitters": False})
    start = time.perf_counter()
    # Welford over the seeds' images, in f64.
    mean = np.zeros((height, width, 3))
    m2 = np.zeros((height, width, 3))
    for s in range(seeds):
        img = np.array(mi.render(scene, integrator=integrator, spp=spp, seed=s), dtype=np.float64)[:, :, :3]
        d = img - mean
        mean += d / (s + 1)
        m2 += d * (img - mean)
    seconds = time.perf_counter() - start
    var_of_mean = m2 / (seeds - 1) / seeds if seeds > 1 else np.zeros_like(mean)
    with open(out + ".tmp", "wb") as f:
        f.write(b"PGMI0001")
        f.write(struct.pack("<IIIId", width, height, seeds, spp, seconds))
        f.write(mean.astype("<f4").tobytes())
        f.write(var_of_mean.astype("<f4").tobytes())
    os.replace(out + ".tmp", out)
    if exr:
        mi.Bitmap(mean.astype(np.float32)).write(exr)


if __name__ == "__main__":
    main()
