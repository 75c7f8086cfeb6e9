// SPDX-License-Identifier: GPL-3.0-or-later
// Articula job type "articula-subjects": one task per subject folder under a shared root, each running
// one Articula batch command on it: learn a rig from its registered scans (learn-rig), or import and
// bake a large scan sequence into a .blend (import-scans).  Written by `./run farm job-types --to DIR`;
// submitted by `./run farm learn` / `./run farm import` (docs/farm.md).

const JOB_TYPE = {
    label: "Articula Subjects",
    description: "One Articula batch command per subject folder: learn rigs, or import sequences",
    settings: [
        { key: "command", type: "string", required: true, choices: ["learn-rig", "import-scans"],
          default: "learn-rig", description: "learn-rig: a model bundle per subject; import-scans: a .blend per subject" },
        { key: "root", type: "string", subtype: "dir_path", required: true,
          description: "Shared folder holding one folder of scans per subject" },
        { key: "subjects", type: "string", required: true,
          description: "Subject folder names under root, separated by '/' (names, not paths)" },
        { key: "out_dir", type: "string", subtype: "dir_path", required: true,
          description: "Shared folder for the results: <subject>.npz (and .json/.blend)" },
        { key: "blend", type: "bool", default: false,
          description: "learn-rig: also save <subject>.blend with the scans and the learned rig" },
        { key: "options", type: "string", default: "",
          description: "Further flags of the command, e.g. --parts 19" },
    ]
};

function compileJob(job) {
    const settings = job.settings;
    const extra = (settings.options || "").split(/\s+/).filter((t) => t.length > 0);
    const names = settings.subjects.split("/").map((t) => t.trim()).filter((t) => t.length > 0);
    if (names.length == 0) throw "no subjects given";
    for (const name of names) {
        const scans = path.join(settings.root, name);
        const out = path.join(settings.out_dir, name);
        let args;
        if (settings.command == "learn-rig") {
            args = ["learn-rig", "--scans", scans, "--out", out + ".npz", "--report", out + ".json"];
            if (settings.blend) args = args.concat(["--blend", out + ".blend"]);
        } else if (settings.command == "import-scans") {
            args = ["import-scans", "--scans", scans, "--name", name, "--blend", out + ".blend"];
        } else {
            throw `command "${settings.command}" is not learn-rig or import-scans`;
        }
        const task = author.Task(`${settings.command} ${name}`, "misc");
        task.addCommand(author.Command("exec", { exe: "{articula}", args: args.concat(extra) }));
        job.addTask(task);
    }
}
