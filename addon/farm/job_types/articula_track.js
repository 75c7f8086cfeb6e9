// SPDX-License-Identifier: GPL-3.0-or-later
// Articula job type "articula-track": a long recording tracked in frame chunks, one task per chunk, then
// one task that merges the chunks into the tracked bundle and bakes it into a .blend.  Without a model (depth
// recordings), a first task adapts the built-in template body to the person and the chunks track with it.
// Written into the Manager's scripts/ folder by `./run farm job-types --to DIR`; submitted by
// `./run farm track` and the Farm panel (docs/farm.md).  {articula} is the Manager variable naming the executable that takes
// Articula's batch commands (articula-batch, or a checkout's ./run).

const JOB_TYPE = {
    label: "Articula Track",
    description: "Track a recording in frame chunks with a model bundle, merge, bake",
    settings: [
        { key: "model", type: "string", subtype: "file_path", default: "",
          description: "Model bundle (.npz) of the person; empty (depth only): the built-in template body, adapted to the person on the first adapt_frames frames by a first task" },
        { key: "adapt_frames", type: "int32", default: 300,
          description: "Without a model: frames the template adapts on before the chunks track with it" },
        { key: "input", type: "string", subtype: "dir_path", required: true,
          description: "Folder of the recording: depth PNG frames, or scans" },
        { key: "input_kind", type: "string", required: true, choices: ["depth", "scans"], default: "depth",
          description: "depth: a depth-camera recording; scans: unregistered scans or point files" },
        { key: "chunks", type: "string", required: true,
          description: "Tracked frame range of every chunk, START:STOP,... (0-based, STOP exclusive)" },
        { key: "run", type: "string", default: "all",
          description: "Chunks this job tracks: 'all', or their numbers (0,3); the others are already tracked" },
        { key: "work_dir", type: "string", subtype: "dir_path", required: true,
          description: "Shared folder for the chunks' bundles and logs" },
        { key: "out", type: "string", subtype: "file_path", required: true,
          description: "Tracked bundle (.npz) the merge writes" },
        { key: "blend", type: "string", subtype: "file_path", default: "",
          description: "Optional .blend the merged action is baked into (added to the file when it exists)" },
        { key: "options", type: "string", default: "",
          description: "Further tracking flags, e.g. --tracker icp --camera kinect_v1" },
        { key: "agree_mm", type: "float", default: 100.0,
          description: "The merge refuses chunks whose posed vertices differ more (mm) where it switches (0: off)" },
        { key: "start_from", type: "string", default: "",
          description: "CHUNK:EARLIER:POSE,...: start a chunk from an earlier chunk's pose (scans; a repair)" },
    ]
};

function parseChunks(text) {
    const out = [];
    for (const item of text.split(",")) {
        const t = item.trim();
        if (!t) continue;
        const m = t.match(/^(\d+):(\d+)$/);
        if (!m || Number(m[1]) >= Number(m[2])) throw `chunk "${t}": expected START:STOP with START < STOP`;
        out.push([Number(m[1]), Number(m[2])]);
    }
    if (out.length == 0) throw "no chunks given";
    return out;
}

function pad(n) { return String(n).padStart(4, "0"); }

function chunkFile(settings, index, range, count) {
    if (count == 1) return settings.out;      // one chunk: it is the tracked bundle, nothing to merge
    return path.join(settings.work_dir, `chunk_${pad(index)}_${pad(range[0])}-${pad(range[1])}.npz`);
}

function selected(settings, count) {
    const run = (settings.run || "all").trim();
    if (run == "all") return [...Array(count).keys()];
    if (run == "" || run == "none") return [];
    return run.split(",").map((t) => {
        const k = Number(t.trim());
        if (!Number.isInteger(k) || k < 0 || k >= count) throw `run: chunk "${t}" is not one of 0..${count - 1}`;
        return k;
    });
}

function startPoses(settings, chunks) {
    const out = {};
    for (const item of (settings.start_from || "").split(",")) {
        const t = item.trim();
        if (!t) continue;
        const m = t.match(/^(\d+):(\d+):(\d+)$/);
        if (!m || Number(m[1]) >= chunks.length || Number(m[2]) >= Number(m[1]))
            throw `start_from "${t}": expected CHUNK:EARLIER_CHUNK:POSE with 0 <= EARLIER_CHUNK < CHUNK < ${chunks.length}`;
        const from = Number(m[2]);
        out[Number(m[1])] = chunkFile(settings, from, chunks[from], chunks.length) + ":" + m[3];
    }
    return out;
}

function compileJob(job) {
    const settings = job.settings;
    const chunks = parseChunks(settings.chunks);
    const extra = (settings.options || "").split(/\s+/).filter((t) => t.length > 0);
    const kind = settings.input_kind == "scans" ? "--scans" : "--depth";
    const starts = startPoses(settings, chunks);
    let model = settings.model, adapt = null;
    if (!model) {
        if (kind != "--depth") throw "scans need the person's model bundle (model)";
        model = path.join(settings.work_dir, "template_adapted.npz");
        const frames = Math.min(settings.adapt_frames, chunks[chunks.length - 1][1]);
        adapt = author.Task(`adapt frames 0:${frames}`, "misc");
        adapt.addCommand(author.Command("exec", {
            exe: "{articula}",
            args: ["track", kind, settings.input, "--frames", `0:${frames}`, "--out", model].concat(extra),
        }));
        job.addTask(adapt);
    }
    const chunkTasks = [];
    for (const k of selected(settings, chunks.length)) {
        const range = chunks[k];
        const task = author.Task(`chunk-${pad(k)} frames ${range[0]}:${range[1]}`, "misc");
        task.addCommand(author.Command("exec", {
            exe: "{articula}",
            args: ["track", "--model", model, kind, settings.input, "--frames", `${range[0]}:${range[1]}`,
                   "--out", chunkFile(settings, k, range, chunks.length)].concat(
                       k in starts ? ["--start-pose", starts[k]] : [], extra),
        }));
        if (adapt) task.addDependency(adapt);
        job.addTask(task);
        chunkTasks.push(task);
    }
    const files = chunks.map((range, k) => chunkFile(settings, k, range, chunks.length));
    const finish = author.Task("merge", "misc");
    if (chunks.length > 1) {
        finish.addCommand(author.Command("exec", {
            exe: "{articula}",
            args: ["merge-tracks"].concat(files, ["--out", settings.out,
                                                  "--report", path.join(settings.work_dir, "merge.json")],
                                          ["--agree", String(settings.agree_mm)]),
        }));
    }
    if (settings.blend) {
        finish.addCommand(author.Command("exec", {
            exe: "{articula}", args: ["build-rig", "--bundle", settings.out, "--blend", settings.blend],
        }));
    }
    if (chunks.length == 1 && !settings.blend) return;
    for (const task of chunkTasks) finish.addDependency(task);
    job.addTask(finish);
}
