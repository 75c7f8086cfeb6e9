@echo off
rem Articula batch commands through Blender, e.g. as the Flamenco variable {articula} on Windows Workers:
rem   articula-batch.cmd track --model m.npz --depth rec\ ...   (%ARTICULA_BLENDER%: the blender.exe to use)
if "%ARTICULA_BLENDER%"=="" set ARTICULA_BLENDER=blender.exe
"%ARTICULA_BLENDER%" -b --python-exit-code 1 -P "%~dp0batch.py" -- %*
exit /b %ERRORLEVEL%
