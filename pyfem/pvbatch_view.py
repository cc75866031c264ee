"""Open a pyfem run in ParaView: the model coloured by region (rock layers, lining, ...), cut open
at the monitoring section, warped by the displacement at its largest, with the interlayer
interfaces coloured by their slip. Writes a picture and a ParaView state file.

Run it with ParaView's own Python (Debian: paraview, python3-paraview; pvbatch needs an X server,
hence xvfb-run), or through `python3 -m pyfem view RUN_DIR`, which does this for you:

    xvfb-run -a pvbatch pyfem/pvbatch_view.py RUN_DIR [--time T] [--section-y Y] [--warp F]

Writes RUN_DIR/plots/paraview.png and RUN_DIR/paraview.pvsm (open the state in the ParaView GUI:
File > Load State, "Search files under specified directory" = RUN_DIR), and prints one line
`PARAVIEW {...}` (JSON: time, peak displacement, points, regions, pictures) for scripts and tests.

What it reads (docs/paraview.md): fields.xdmf (point data displacement, and with contact pair_slip,
pair_D at the pair nodes; cell data region), run.json (regions: name -> id; monitors).
"""
import argparse
import json
import os
import sys

from paraview import simple as pv


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="pvbatch_view.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", help="a pyfem run directory (holds fields.xdmf and run.json)")
    parser.add_argument("--time", type=float, default=None,
                        help="output time to show (s); default: the time of the largest displacement")
    parser.add_argument("--section-y", type=float, default=None,
                        help="y of the cut (m); default: the monitors' mean y, else the model's middle")
    parser.add_argument("--warp", type=float, default=None,
                        help="displacement magnification; default: the largest displacement drawn as 3 %% "
                             "of the model's size")
    parser.add_argument("--png", default=None, help="picture path (default RUN_DIR/plots/paraview.png)")
    return parser.parse_args(argv)


def region_colours(names):
    """A distinct colour per region: lining-like names grey, the rest from a qualitative palette."""
    palette = [(0.80, 0.60, 0.35), (0.45, 0.62, 0.80), (0.55, 0.75, 0.45), (0.85, 0.45, 0.45),
               (0.65, 0.50, 0.80), (0.90, 0.80, 0.40), (0.45, 0.75, 0.75)]
    colours, k = {}, 0
    for name in names:
        if "lining" in name or "concrete" in name:
            colours[name] = (0.55, 0.55, 0.55)
        else:
            colours[name] = palette[k % len(palette)]
            k += 1
    return colours


def main(argv):
    args = parse_arguments(argv)
    run_dir = os.path.abspath(args.run_dir)
    xdmf = os.path.join(run_dir, "fields.xdmf")
    if not os.path.exists(xdmf):
        print(f"error: {xdmf} does not exist (a run writes it when output.xdmf_interval > 0)", file=sys.stderr)
        return 2
    with open(os.path.join(run_dir, "run.json")) as stream:
        summary = json.load(stream)
    regions = summary.get("regions") or {}

    # ParaView's XDMF (2) reader reads meshio's time series; the file's bare "mesh" grid is left out.
    reader = pv.XDMFReader(registrationName="fields", FileNames=[xdmf])
    reader.UpdatePipelineInformation()
    reader.GridStatus = [grid for grid in reader.GridStatus if grid != "mesh"]
    reader.UpdatePipelineInformation()
    times = list(reader.TimestepValues) or [0.0]
    point_arrays = set(reader.PointData.keys())
    if "displacement" not in point_arrays:
        print("error: fields.xdmf has no displacement (output.fields must include \"displacement\")",
              file=sys.stderr)
        return 2
    peak_time, peak = times[0], -1.0
    for t in times:
        reader.UpdatePipeline(t)
        largest = reader.PointData["displacement"].GetRange(-1)[1]  # -1: the vector's magnitude
        if largest > peak:
            peak_time, peak = t, largest
    shown_time = peak_time if args.time is None else min(times, key=lambda t: abs(t - args.time))
    reader.UpdatePipeline(shown_time)
    bounds = reader.GetDataInformation().GetBounds()
    size = max(bounds[1] - bounds[0], bounds[3] - bounds[2], bounds[5] - bounds[4])
    if args.section_y is not None:
        section_y = args.section_y
    else:
        monitor_y = [m["point"][1] for m in summary.get("scene", {}).get("monitor", []) if "point" in m]
        section_y = sum(monitor_y) / len(monitor_y) if monitor_y else 0.5 * (bounds[2] + bounds[3])
    displacement_here = reader.PointData["displacement"].GetRange(-1)[1]
    warp_factor = args.warp if args.warp is not None else (
        0.03 * size / displacement_here if displacement_here > 0.0 else 0.0)

    view = pv.GetActiveViewOrCreate("RenderView")
    view.ViewSize = [800, 600]
    view.ViewTime = shown_time
    view.UseColorPaletteForBackground = 0
    view.Background = [1.0, 1.0, 1.0]
    view.OrientationAxesVisibility = 1

    warp = pv.WarpByVector(registrationName="deformed", Input=reader)
    warp.Vectors = ["POINTS", "displacement"]
    warp.ScaleFactor = warp_factor
    # The model cut open at the section: the half with y below it, so the cavern's section faces
    # the camera, coloured by region.
    clip = pv.Clip(registrationName="cut at the section", Input=warp)
    clip.ClipType = "Plane"
    clip.ClipType.Origin = [0.0, section_y, 0.0]
    clip.ClipType.Normal = [0.0, 1.0, 0.0]
    clip.Crinkleclip = 0
    clip_display = pv.Show(clip, view)
    pv.ColorBy(clip_display, ("CELLS", "region"))
    lut = pv.GetColorTransferFunction("region")
    lut.InterpretValuesAsCategories = 1
    names = sorted(regions, key=lambda name: regions[name])
    lut.Annotations = [item for name in names for item in (str(regions[name]), name)]
    colours = region_colours(names)
    lut.IndexedColors = [c for name in names for c in colours[name]]
    clip_display.SetScalarBarVisibility(view, True)
    clip_display.EdgeColor = [0.25, 0.25, 0.25]
    clip_display.SetRepresentationType("Surface With Edges")

    bar = pv.GetScalarBar(lut, view)
    bar.TitleColor = bar.LabelColor = [0.0, 0.0, 0.0]
    bar.Title = "region"

    shown = {"regions": names, "interfaces": False}
    views = [view]
    if "pair_D" in point_arrays:
        # A second view: the interlayer interfaces coloured by their slip, with the lining. The split
        # interfaces are surfaces of the mesh (their two sides share no node): the surface facets
        # whose every node is a pair node (pair_D > 0 there, 0 elsewhere).
        interface_view = pv.CreateView("RenderView")
        interface_view.ViewSize = view.ViewSize
        interface_view.ViewTime = shown_time
        interface_view.UseColorPaletteForBackground = 0
        interface_view.Background = [1.0, 1.0, 1.0]
        surface = pv.ExtractSurface(registrationName="surfaces", Input=warp)
        interfaces = pv.Threshold(registrationName="interfaces", Input=surface)
        interfaces.Scalars = ["POINTS", "pair_D"]
        interfaces.LowerThreshold = 1.0e-12
        interfaces.UpperThreshold = 1.0e30
        interfaces.AllScalars = 1
        interface_display = pv.Show(interfaces, interface_view)
        pv.ColorBy(interface_display, ("POINTS", "pair_slip"))
        slip_lut = pv.GetColorTransferFunction("pair_slip")
        slip_lut.ApplyPreset("Inferno (matplotlib)", True)
        interface_display.RescaleTransferFunctionToDataRange(True, False)
        interface_display.SetScalarBarVisibility(interface_view, True)
        slip_bar = pv.GetScalarBar(slip_lut, interface_view)
        slip_bar.TitleColor = slip_bar.LabelColor = [0.0, 0.0, 0.0]
        slip_bar.Title = "interface slip (m)"
        slip_bar.ComponentTitle = ""
        lining_ids = [regions[name] for name in names if "lining" in name or "concrete" in name]
        if lining_ids:
            lining = pv.Threshold(registrationName="lining", Input=warp)
            lining.Scalars = ["CELLS", "region"]
            lining.LowerThreshold = min(lining_ids)
            lining.UpperThreshold = max(lining_ids)
            lining_display = pv.Show(lining, interface_view)
            pv.ColorBy(lining_display, None)
            lining_display.AmbientColor = lining_display.DiffuseColor = [0.55, 0.55, 0.55]
        label = pv.Text(registrationName="interfaces title")
        label.Text = "interlayer interfaces (coloured by slip) and the lining"
        label_display = pv.Show(label, interface_view)
        label_display.Color = [0.0, 0.0, 0.0]
        label_display.FontSize = 9
        label_display.WindowLocation = "Upper Left Corner"
        views.append(interface_view)
        shown["interfaces"] = True

    text = pv.Text(registrationName="title")
    text.Text = (f"{summary.get('scene', {}).get('title', os.path.basename(run_dir))}\n"
                 f"t = {shown_time:g} s, largest displacement {displacement_here:.3g} m, "
                 f"drawn x{warp_factor:.3g}; cut at y = {section_y:g} m")
    text_display = pv.Show(text, view)
    text_display.Color = [0.0, 0.0, 0.0]
    text_display.FontSize = 9
    text_display.WindowLocation = "Upper Left Corner"

    centre = [0.5 * (bounds[0] + bounds[1]), section_y, 0.5 * (bounds[4] + bounds[5])]
    for each in views:
        each.CameraFocalPoint = centre
        # From the side the cut faces (+y; the clip keeps y below the section), above and to the right.
        each.CameraPosition = [centre[0] + 0.9 * size, section_y + 2.2 * size, centre[2] + 0.7 * size]
        each.CameraViewUp = [0.0, 0.0, 1.0]
        each.ResetCamera()

    png = os.path.abspath(args.png or os.path.join(run_dir, "plots", "paraview.png"))
    os.makedirs(os.path.dirname(png), exist_ok=True)
    layout = pv.GetLayout(view)
    if len(views) > 1:
        layout.SplitHorizontal(0, 0.5)
        layout.AssignView(2, views[1])
    width, height = 800 * len(views), 600
    pv.SaveScreenshot(png, layout, SaveAllViews=1, ImageResolution=[width, height])
    state = os.path.join(run_dir, "paraview.pvsm")
    pv.SaveState(state)
    info = reader.GetDataInformation()
    print("PARAVIEW " + json.dumps({"time": shown_time, "peak_time": peak_time, "peak": peak,
                                    "shown_displacement": displacement_here, "warp": warp_factor,
                                    "points": info.GetNumberOfPoints(), "section_y": section_y,
                                    "png": png, "state": state, **shown}))
    return 0


if __name__ == "__main__":
    status = main(sys.argv[1:])
    sys.stdout.flush()
    sys.stderr.flush()
    # ParaView 5.11 under Xvfb reports GLXBadContext while it tears its windows down, after the
    # picture and the state are written, and exits with 1: leave without the teardown.
    os._exit(status)
