// node standin/compile.js JOB_TYPE.js SUBMITTED_JOB.json: compile a submitted job with the stand-in, print
// the authored tasks as JSON ([{name, type, priority, commands: [{name, parameters, totalStepCount}], dependencies}]) or the error (exit 1).
"use strict";

const fs = require("fs");
const { loadJobType, jobTypeName } = require("./flamenco_standin.js");

const [script, jobFile] = process.argv.slice(2);
const submitted = JSON.parse(fs.readFileSync(jobFile, "utf8"));
if (submitted.type !== jobTypeName(script)) {
    console.error("job type " + JSON.stringify(submitted.type) + " is not " + jobTypeName(script));
    process.exit(1);
}
try {
    process.stdout.write(JSON.stringify(loadJobType(script).compile(submitted).tasks));
} catch (e) {
    console.error(String(e));
    process.exit(1);
}
