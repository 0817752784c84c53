// Flamenco job type: render a USD shot's frames with petzval, one task per chunk of frames.
// Install: copy into the Flamenco Manager's `scripts/` folder and restart the Manager.
// Each chunk runs `petzval render SHOT --frames A-B -o OUTPUT [--camera PRIM] [extra]`
// through the Worker's `exec` command; petzval writes each EXR to a temporary name and
// renames it when complete, so a failed task leaves no broken frame (Flamenco retries it).

const JOB_TYPE = {
  label: "Petzval USD render",
  description: "Render the frames of a USD shot through real lenses with petzval",
  settings: [
    { key: "shot", type: "string", subtype: "file_path", required: true,
      description: "The USD shot (.usd, .usda, .usdc, .usdz)" },
    { key: "frames", type: "string", required: true,
      description: "Frames to render, e.g. '1001-1010' or '1,5,10-20'" },
    { key: "chunk_size", type: "int32", default: 1, propargs: { min: 1 },
      description: "Frames per task" },
    { key: "render_output_path", type: "string", subtype: "file_path", required: true,
      description: "Output pattern; a run of # is the frame, e.g. /renders/shot.####.exr" },
    { key: "camera", type: "string", required: false,
      description: "Camera prim path (default: the RenderSettings' or the first camera)" },
    { key: "petzval", type: "string", default: "petzval",
      description: "The petzval binary on the Workers" },
    { key: "extra_args", type: "string", required: false,
      description: "More petzval render options, e.g. '--spp 256 --lens-model auto'" },
  ],
};

// "1001-1004" → [[1001, 1004]]; "1,5-7" → [[1, 1], [5, 7]]
function frameRanges(chunk) {
  return String(chunk).split(",").map((part) => {
    const m = part.trim().match(/^(-?\d+)(?:-(-?\d+))?$/);
    if (!m) {
      throw new Error(`cannot read frames '${part}'`);
    }
    const a = parseInt(m[1], 10);
    const b = m[2] === undefined ? a : parseInt(m[2], 10);
    return [a, b];
  });
}

function compileJob(job) {
  const settings = job.settings;
  if (!/#+/.test(settings.render_output_path)) {
    throw new Error("render_output_path must name the frame with #### (e.g. shot.####.exr)");
  }
  const common = ["--no-png"];
  if (settings.camera) {
    common.push("--camera", settings.camera);
  }
  if (settings.extra_args) {
    common.push(...settings.extra_args.split(/\s+/).filter((s) => s.length > 0));
  }
  for (const chunk of frameChunker(settings.frames, settings.chunk_size)) {
    const task = author.Task(`render-${chunk}`, "misc");
    for (const [a, b] of frameRanges(chunk)) {
      const frames = a === b ? ["--frame", String(a)] : ["--frames", `${a}-${b}`];
      task.addCommand(author.Command("exec", {
        exe: settings.petzval,
        args: ["render", settings.shot, ...frames, "-o", settings.render_output_path, ...common],
      }));
    }
    job.addTask(task);
  }
}
