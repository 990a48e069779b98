// A small stand-in for the Flamenco Manager's job compiler, for testing job types under Node.
//
// It runs a job type script the way the Manager does (internal/manager/job_compilers in Flamenco 3):
// as one plain script in strict mode (goja.Compile(..., strict=true)), with the globals the Manager
// sets (print, alert, author, path, ...), then calls compileJob(job) on a job made from a submitted
// job, as Flamenco's AuthoredJob exposes it to scripts (lower-case field and method names:
// job.settings, job.metadata, job.name, job.addTask(task); task.addCommand(cmd)). author.Task and
// author.Command build the same records as Flamenco's author.go; path.join/basename/dirname/stem
// follow Flamenco's crosspath package (Go's path functions after turning backslashes into slashes).
"use strict";

const fs = require("fs");
const nodePath = require("path");
const vm = require("vm");

function toSlash(p) {
    return String(p).replace(/\\/g, "/");
}

// Go's path.Join: join the non-empty elements with "/" and Clean the result.
function goJoin(elems) {
    const parts = elems.filter(function (e) { return e !== ""; });
    if (parts.length === 0) {
        return "";
    }
    let joined = nodePath.posix.normalize(parts.join("/"));
    if (joined.length > 1 && joined.endsWith("/")) {
        joined = joined.slice(0, -1);
    }
    return joined;
}

const crosspath = {
    join: function () { return toSlash(goJoin(Array.prototype.slice.call(arguments))); },
    basename: function (p) { return nodePath.posix.basename(toSlash(p)) || (p === "" ? "." : "/"); },
    dirname: function (p) {
        if (p === "") { return "."; }
        const s = toSlash(p);
        const i = s.lastIndexOf("/");
        if (i < 0) { return "."; }
        return i === 0 ? "/" : s.slice(0, i);
    },
    stem: function (p) {
        const base = nodePath.posix.basename(toSlash(p));
        return base.slice(0, base.length - nodePath.posix.extname(base).length);
    },
};

let uuidCounter = 0;

function makeAuthor() {
    return {
        Task: function (name, taskType) {
            name = String(name).trim();
            taskType = String(taskType).trim();
            if (name === "") { throw new Error("author.Task(name, type): name is required"); }
            if (taskType === "") { throw new Error("author.Task(name, type): type is required"); }
            const task = {
                uuid: "task-" + (++uuidCounter), name: name, type: taskType, priority: 50,
                commands: [], dependencies: [],
                addCommand: function (cmd) { task.commands.push(cmd); },
                addDependency: function (dep) { task.dependencies.push(dep); },
            };
            return task;
        },
        Command: function (cmdName, parameters, totalStepCount) {
            return { name: cmdName, parameters: parameters, totalStepCount: totalStepCount || 0 };
        },
    };
}

// Load a job type script; returns {jobType, compile(submittedJob) -> {tasks, log}}.
function loadJobType(file) {
    const source = fs.readFileSync(file, "utf8");
    const log = [];
    const context = vm.createContext({
        print: function () { log.push(Array.prototype.slice.call(arguments).join(" ")); },
        alert: function () { log.push("ALERT " + Array.prototype.slice.call(arguments).join(" ")); },
        author: makeAuthor(),
        path: crosspath,
        process: {},
        shellSplit: function (s) { return String(s).split(/\s+/).filter(Boolean); },
        formatTimestampLocal: function (t) { return new Date(t).toISOString(); },
    });
    vm.runInContext("\"use strict\";\n" + source, context, { filename: nodePath.basename(file) });
    // plain data of this realm (the script's objects belong to the vm context's realm)
    const plain = function (value) { return JSON.parse(JSON.stringify(value)); };
    const jobType = plain(vm.runInContext("JOB_TYPE", context));
    if (typeof context.compileJob !== "function") {
        throw new Error(file + " does not define a compileJob(job) function");
    }
    return {
        jobType: jobType,
        source: source,
        log: log,
        compile: function (submitted) {
            const job = {
                jobID: "job-1", name: submitted.name, jobType: submitted.type, priority: submitted.priority,
                created: new Date(0),
                settings: Object.assign({}, submitted.settings || {}),
                metadata: Object.assign({}, submitted.metadata || {}),
                tasks: [],
                addTask: function (task) { job.tasks.push(task); },
            };
            context.compileJob(job);
            return {
                settings: plain(job.settings),
                tasks: job.tasks.map(function (t) {
                    return {
                        name: t.name, type: t.type, priority: t.priority,
                        commands: plain(t.commands),
                        dependencies: t.dependencies.map(function (d) { return d.name; }),
                    };
                }),
            };
        },
    };
}

// Flamenco names a job type after its file: mc_ao_bake.js -> "mc-ao-bake".
function jobTypeName(file) {
    return nodePath.basename(file, nodePath.extname(file)).replace(/_/g, "-");
}

module.exports = { loadJobType: loadJobType, jobTypeName: jobTypeName, crosspath: crosspath };
