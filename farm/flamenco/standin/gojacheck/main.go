// gojacheck runs a Flamenco job type script in goja, the JavaScript engine the Flamenco Manager runs
// job types in, set up as the Manager sets it up (Flamenco 3, internal/manager/job_compilers):
// strict mode, lower-case field names for Go values, the print/alert globals and the author and
// path modules, with compileJob(job) called on an AuthoredJob. Usage:
//
//	go run . JOB_TYPE.js SUBMITTED_JOB.json
//
// prints the authored tasks as JSON, like ../compile.js does under Node, or the error (exit 1).
package main

import (
	"encoding/json"
	"errors"
	"fmt"
	"os"
	pathpkg "path"
	"path/filepath"
	"strings"

	"github.com/dop251/goja"
)

type AuthoredCommand struct {
	Name           string                 `json:"name"`
	Parameters     map[string]interface{} `json:"parameters"`
	TotalStepCount int                    `json:"totalStepCount"`
}

type AuthoredTask struct {
	Name         string            `json:"name"`
	Type         string            `json:"type"`
	Priority     int               `json:"priority"`
	Commands     []AuthoredCommand `json:"commands"`
	Dependencies []*AuthoredTask   `json:"-"`
}

func (at *AuthoredTask) AddCommand(ac *AuthoredCommand)       { at.Commands = append(at.Commands, *ac) }
func (at *AuthoredTask) AddDependency(dep *AuthoredTask) error { at.Dependencies = append(at.Dependencies, dep); return nil }

type AuthoredJob struct {
	JobID    string
	Name     string
	JobType  string
	Priority int
	Settings map[string]interface{}
	Metadata map[string]string
	Tasks    []AuthoredTask
}

func (aj *AuthoredJob) AddTask(at *AuthoredTask) { aj.Tasks = append(aj.Tasks, *at) }

type author struct{}

func (author) Task(name string, taskType string) (*AuthoredTask, error) {
	name, taskType = strings.TrimSpace(name), strings.TrimSpace(taskType)
	if name == "" {
		return nil, errors.New("author.Task(name, type): name is required")
	}
	if taskType == "" {
		return nil, errors.New("author.Task(name, type): type is required")
	}
	return &AuthoredTask{name, taskType, 50, []AuthoredCommand{}, []*AuthoredTask{}}, nil
}

func (author) Command(cmdName string, parameters map[string]interface{}, totalStepCount int) (*AuthoredCommand, error) {
	return &AuthoredCommand{cmdName, parameters, totalStepCount}, nil
}

// Flamenco's crosspath functions.
func toSlash(p string) string { return strings.ReplaceAll(p, "\\", "/") }
func join(elem ...string) string { return toSlash(pathpkg.Join(elem...)) }
func base(p string) string      { return pathpkg.Base(toSlash(p)) }
func stem(p string) string {
	b := base(p)
	return b[:len(b)-len(pathpkg.Ext(b))]
}
func dir(p string) string {
	if p == "" {
		return "."
	}
	d, _ := pathpkg.Split(toSlash(p))
	switch {
	case d == "":
		return "."
	case len(d) > 1:
		return d[:len(d)-1]
	}
	return d
}

func main() {
	if len(os.Args) != 3 {
		fmt.Fprintln(os.Stderr, "usage: gojacheck JOB_TYPE.js SUBMITTED_JOB.json")
		os.Exit(2)
	}
	src, err := os.ReadFile(os.Args[1])
	must(err)
	raw, err := os.ReadFile(os.Args[2])
	must(err)
	var submitted struct {
		Name     string                 `json:"name"`
		Type     string                 `json:"type"`
		Priority int                    `json:"priority"`
		Settings map[string]interface{} `json:"settings"`
		Metadata map[string]string      `json:"metadata"`
	}
	must(json.Unmarshal(raw, &submitted))

	name := filepath.Base(os.Args[1])
	jobType := strings.ReplaceAll(strings.TrimSuffix(name, filepath.Ext(name)), "_", "-")
	if submitted.Type != jobType {
		fail(fmt.Errorf("job type %q is not %q", submitted.Type, jobType))
	}
	program, err := goja.Compile(name, string(src), true)
	must(err)

	vm := goja.New()
	vm.SetFieldNameMapper(goja.UncapFieldNameMapper())
	noop := func(call goja.FunctionCall) goja.Value { return goja.Undefined() }
	must(vm.Set("print", noop))
	must(vm.Set("alert", noop))
	// Flamenco exports the author module's members under these exact names (author.go)
	authorModule := vm.NewObject()
	must(authorModule.Set("Task", author{}.Task))
	must(authorModule.Set("Command", author{}.Command))
	must(vm.Set("author", authorModule))
	must(vm.Set("path", map[string]interface{}{"join": join, "basename": base, "dirname": dir, "stem": stem}))
	_, err = vm.RunProgram(program)
	must(err)
	if vm.Get("JOB_TYPE") == nil {
		fail(errors.New("the script does not define JOB_TYPE"))
	}
	compileJob, ok := goja.AssertFunction(vm.Get("compileJob"))
	if !ok {
		fail(errors.New("the script does not define a compileJob(job) function"))
	}
	job := &AuthoredJob{JobID: "job-1", Name: submitted.Name, JobType: submitted.Type, Priority: submitted.Priority,
		Settings: submitted.Settings, Metadata: submitted.Metadata}
	if job.Settings == nil {
		job.Settings = map[string]interface{}{}
	}
	if _, err := compileJob(nil, vm.ToValue(job)); err != nil {
		fail(err)
	}
	type taskOut struct {
		AuthoredTask
		Deps []string `json:"dependencies"`
	}
	out := make([]taskOut, 0, len(job.Tasks))
	for _, t := range job.Tasks {
		deps := []string{}
		for _, d := range t.Dependencies {
			deps = append(deps, d.Name)
		}
		out = append(out, taskOut{t, deps})
	}
	must(json.NewEncoder(os.Stdout).Encode(out))
}

func must(err error) {
	if err != nil {
		fail(err)
	}
}

func fail(err error) {
	fmt.Fprintln(os.Stderr, err)
	os.Exit(1)
}
