// SPDX-License-Identifier: GPL-3.0-or-later
//
// Flamenco job type "mc-ao-bake": bake ambient occlusion of an asset library with mc_ao.
//
// Install: copy this file into the "scripts" folder next to the Flamenco Manager executable and
// restart the Manager. Submit jobs with mc_ao's batch script, which plans the tasks from a manifest
// (leaving out those already done) and posts the job to the Manager:
//
//   python scripts/bake_batch.py MANIFEST --output DIR --runner flamenco --manager http://manager:8080
//
// Each .blend file becomes one task of type "blender" with one "blender-render" command that runs
// scripts/bake_ao.py on that file, the same entry point and arguments as bake_batch.py's local
// runner:
//
//   {blender} {blenderArgs} --background FILE --python-exit-code 1
//       --python MC_AO_ROOT/scripts/bake_ao.py -- SETTINGS --output OUTPUT_ROOT/NAME
//       --summary-json OUTPUT_ROOT/NAME/mc_ao-FINGERPRINT.json --threads N --quiet
//
// A broken asset fails its own task (bake_ao.py exits 1 or 2); Flamenco retries and reports it.
// Plain JavaScript as Flamenco's engine (goja) runs it, in strict mode: no modules, no classes,
// no newer syntax.

const JOB_TYPE = {
    label: "mc_ao: Bake AO of an asset library",
    description: "One Blender task per .blend file of an mc_ao batch manifest (submit with scripts/bake_batch.py --runner flamenco)",
    settings: [
        { key: "tasks", type: "string", required: true, visible: "hidden",
          description: "The planned tasks as JSON: [{name, blend, args, summary, threads}], written by bake_batch.py" },
        { key: "output_root", type: "string", subtype: "dir_path", required: true, visible: "web",
          description: "Output folder; each .blend file bakes into output_root/<name>/" },
        { key: "mc_ao_root", type: "string", subtype: "dir_path", required: true, visible: "web",
          description: "The mc_ao checkout (with scripts/bake_ao.py) as the Workers see it" },
    ]
};

// A task name becomes a folder: one plain path component.
const SAFE_NAME = /^[^\/\\\x00]+$/;
const SUMMARY_NAME = /^mc_ao-[0-9a-f]{16}\.json$/;

function compileJob(job) {
    const settings = job.settings;
    const root = trimSeparators(requiredString(settings, "mc_ao_root"));
    const outputRoot = trimSeparators(requiredString(settings, "output_root"));
    const plan = parsePlan(settings.tasks);
    const script = path.join(root, "scripts", "bake_ao.py");

    print("mc_ao: " + plan.length + " .blend files to bake into " + outputRoot);
    for (let i = 0; i < plan.length; i++) {
        job.addTask(authorBakeTask(plan[i], script, outputRoot));
    }
}

function authorBakeTask(entry, script, outputRoot) {
    const outDir = path.join(outputRoot, entry.name);
    const args = ["--python-exit-code", "1", "--python", script, "--"]
        .concat(entry.args)
        .concat([
            "--output", outDir,
            "--summary-json", path.join(outDir, entry.summary),
            "--threads", String(entry.threads),
            "--quiet",
        ]);
    const task = author.Task("bake-" + entry.name, "blender");
    task.addCommand(author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: ["--background"],
        blendfile: entry.blend,
        args: args,
    }));
    return task;
}

// Flamenco's path.join cleans only forward slashes: "C:\\mc_ao\\" + "scripts" would give
// "C:/mc_ao//scripts". Drop trailing separators of either kind first (a bare root stays).
function trimSeparators(p) {
    const trimmed = p.replace(/[\/\\]+$/, "");
    return trimmed === "" ? p.charAt(0) : trimmed;
}

function requiredString(settings, key) {
    const value = settings[key];
    if (typeof value !== "string" || value === "") {
        throw "mc_ao: the job setting '" + key + "' is required";
    }
    return value;
}

// The "tasks" setting: a JSON array of {name, blend, args, summary, threads}, checked entry by entry
// so that a bad job is refused at submission with a message naming the entry.
function parsePlan(text) {
    if (typeof text !== "string" || text === "") {
        throw "mc_ao: the job setting 'tasks' is required (submit with scripts/bake_batch.py --runner flamenco)";
    }
    let plan;
    try {
        plan = JSON.parse(text);
    } catch (e) {
        throw "mc_ao: the job setting 'tasks' is not JSON: " + e;
    }
    if (!Array.isArray(plan) || plan.length === 0) {
        throw "mc_ao: the job setting 'tasks' must be a non-empty list of tasks";
    }
    const names = {};
    for (let i = 0; i < plan.length; i++) {
        const entry = plan[i];
        const where = "mc_ao: task " + (i + 1);
        if (entry === null || typeof entry !== "object" || Array.isArray(entry)) {
            throw where + " is not an object";
        }
        if (typeof entry.name !== "string" || !SAFE_NAME.test(entry.name) || entry.name === "." || entry.name === "..") {
            throw where + ": name must be one plain folder name, not " + JSON.stringify(entry.name);
        }
        if (Object.prototype.hasOwnProperty.call(names, entry.name.toLowerCase())) {
            throw where + ": name " + JSON.stringify(entry.name) + " is used by task " + names[entry.name.toLowerCase()];
        }
        names[entry.name.toLowerCase()] = i + 1;
        if (typeof entry.blend !== "string" || entry.blend === "") {
            throw where + " (" + entry.name + "): blend must be the path of a .blend file";
        }
        if (!Array.isArray(entry.args)) {
            throw where + " (" + entry.name + "): args must be a list of strings";
        }
        for (let j = 0; j < entry.args.length; j++) {
            if (typeof entry.args[j] !== "string") {
                throw where + " (" + entry.name + "): args must be a list of strings, not " + JSON.stringify(entry.args[j]);
            }
        }
        if (typeof entry.summary !== "string" || !SUMMARY_NAME.test(entry.summary)) {
            throw where + " (" + entry.name + "): summary must be a name like mc_ao-<16 hex digits>.json";
        }
        if (typeof entry.threads !== "number" || entry.threads < 0 || Math.floor(entry.threads) !== entry.threads) {
            throw where + " (" + entry.name + "): threads must be a whole number >= 0";
        }
    }
    return plan;
}
