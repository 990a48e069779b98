// The mc-ao-bake job type under Node's test runner (node --test farm/flamenco/), with a stand-in for
// the Flamenco Manager's job compiler (flamenco_standin.js).
"use strict";

const test = require("node:test");
const assert = require("node:assert");
const path = require("path");
const { loadJobType, jobTypeName } = require("./standin/flamenco_standin.js");

const SCRIPT = path.join(__dirname, "mc_ao_bake.js");
const SUMMARY_A = "mc_ao-0123456789abcdef.json";
const SUMMARY_B = "mc_ao-fedcba9876543210.json";

function submitted(plan, settings) {
    return {
        name: "mc_ao bake props", type: "mc-ao-bake", priority: 50, submitter_platform: "linux",
        settings: Object.assign({
            mc_ao_root: "/farm/mc_ao", output_root: "/renders/ao", tasks: JSON.stringify(plan),
        }, settings || {}),
        metadata: {},
    };
}

const PLAN = [
    { name: "chair", blend: "/library/props/chair.blend", args: ["--format", "exr", "--samples", "256"],
      summary: SUMMARY_A, threads: 0 },
    { name: "lamp-2f7111f7", blend: "/library/more/lamp.blend", args: ["--objects", "Shade", "Bulb"],
      summary: SUMMARY_B, threads: 4 },
];

test("the job type is named after its file and declares its settings", function () {
    assert.strictEqual(jobTypeName(SCRIPT), "mc-ao-bake");
    const jt = loadJobType(SCRIPT).jobType;
    assert.ok(jt.label.length > 0);
    const keys = jt.settings.map(function (s) { return s.key; });
    assert.deepStrictEqual(keys.sort(), ["mc_ao_root", "output_root", "tasks"]);
    for (const s of jt.settings) {
        assert.ok(["string", "int32", "float", "bool"].includes(s.type), s.key + ": " + s.type);
        assert.strictEqual(s.required, true, s.key);
    }
});

test("one blender-render task per .blend file, running bake_ao.py on it", function () {
    const job = loadJobType(SCRIPT).compile(submitted(PLAN));
    assert.strictEqual(job.tasks.length, 2);
    const [chair, lamp] = job.tasks;
    assert.strictEqual(chair.name, "bake-chair");
    assert.strictEqual(chair.type, "blender");
    assert.strictEqual(chair.commands.length, 1);
    assert.strictEqual(chair.commands[0].name, "blender-render");
    assert.deepStrictEqual(chair.commands[0].parameters, {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: ["--background"],
        blendfile: "/library/props/chair.blend",
        args: [
            "--python-exit-code", "1", "--python", "/farm/mc_ao/scripts/bake_ao.py", "--",
            "--format", "exr", "--samples", "256",
            "--output", "/renders/ao/chair", "--summary-json", "/renders/ao/chair/" + SUMMARY_A,
            "--threads", "0", "--quiet",
        ],
    });
    assert.strictEqual(lamp.name, "bake-lamp-2f7111f7");
    const args = lamp.commands[0].parameters.args;
    assert.deepStrictEqual(args.slice(args.indexOf("--") + 1, args.indexOf("--output")), ["--objects", "Shade", "Bulb"]);
    assert.deepStrictEqual(args.slice(args.indexOf("--threads"), args.indexOf("--threads") + 2), ["--threads", "4"]);
    // tasks are independent: any worker, any order
    assert.deepStrictEqual(chair.dependencies, []);
    assert.deepStrictEqual(lamp.dependencies, []);
});

test("paths are joined as Flamenco joins them (forward slashes), without a doubled separator", function () {
    const job = loadJobType(SCRIPT).compile(submitted(PLAN.slice(0, 1), {
        mc_ao_root: "C:\\tools\\mc_ao\\", output_root: "/renders/ao/",
    }));
    const args = job.tasks[0].commands[0].parameters.args;
    assert.strictEqual(args[args.indexOf("--python") + 1], "C:/tools/mc_ao/scripts/bake_ao.py");
    assert.strictEqual(args[args.indexOf("--output") + 1], "/renders/ao/chair");
});

function refused(plan, settings, message) {
    assert.throws(function () { loadJobType(SCRIPT).compile(submitted(plan, settings)); },
        function (e) { return typeof e === "string" && e.indexOf(message) >= 0; }, message);
}

test("a bad job is refused with a message naming the task", function () {
    refused(PLAN, { tasks: "" }, "the job setting 'tasks' is required");
    refused(PLAN, { tasks: "[{" }, "the job setting 'tasks' is not JSON");
    refused([], null, "must be a non-empty list");
    refused(PLAN, { mc_ao_root: "" }, "the job setting 'mc_ao_root' is required");
    refused(PLAN, { output_root: 7 }, "the job setting 'output_root' is required");
    const bad = function (change) {
        return [PLAN[0], Object.assign({}, PLAN[1], change)];
    };
    refused(bad({ name: "../etc" }), null, "task 2: name must be one plain folder name");
    refused(bad({ name: ".." }), null, "task 2: name must be one plain folder name");
    refused(bad({ name: "a\\b" }), null, "task 2: name must be one plain folder name");
    refused(bad({ name: "Chair" }), null, "task 2: name \"Chair\" is used by task 1");
    refused(bad({ blend: "" }), null, "task 2 (lamp-2f7111f7): blend must be the path");
    refused(bad({ args: "--samples 4" }), null, "args must be a list of strings");
    refused(bad({ args: ["--samples", 4] }), null, "args must be a list of strings, not 4");
    refused(bad({ summary: "../x.json" }), null, "summary must be a name like");
    refused(bad({ threads: -1 }), null, "threads must be a whole number");
    refused(bad({ threads: 1.5 }), null, "threads must be a whole number");
    refused([null], null, "task 1 is not an object");
});

test("plain JavaScript as Flamenco's goja runs it: one script, no modules or newer syntax", function () {
    const source = loadJobType(SCRIPT).source.replace(/\/\/.*$/gm, "");
    for (const word of [/\bimport\b/, /\bexport\b/, /\brequire\s*\(/, /\bclass\s/, /\basync\b/, /\bawait\b/,
                        /\?\./, /\?\?/, /\.\.\.[A-Za-z_]/, /=>/]) {
        assert.ok(!word.test(source), "uses " + word);
    }
});
